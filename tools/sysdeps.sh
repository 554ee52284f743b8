#!/bin/sh
# System libraries, installed with apt when we are root on Debian/Ubuntu; otherwise we say exactly
# what to install. Everything else comes from PyPI into .venv.
# - off-screen rendering (femodes.viz: pyvista/VTK through EGL on Mesa's software renderer);
# - the optional sparse direct back-ends (femodes.sparse_direct, built by tools/fast_backends.sh):
#   SuiteSparse (CHOLMOD) and sequential MUMPS, with OpenBLAS (Debian's reference BLAS would erase
#   CHOLMOD's gain). Without them femodes uses SuperLU.
PKGS=""
if ! (ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libgbm.so.1'); then
    PKGS="libegl1 libgl1-mesa-dri"
fi
if [ ! -f /usr/include/suitesparse/cholmod.h ] || [ ! -f /usr/include/dmumps_c.h ] || \
   ! (ldconfig -p 2>/dev/null | grep -q 'libopenblas'); then
    PKGS="$PKGS libsuitesparse-dev libmumps-seq-dev libopenblas0-pthread"
fi
if [ -z "$PKGS" ]; then
    exit 0
fi
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing $PKGS (off-screen rendering for femodes.viz; sparse direct back-ends)"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $PKGS >/dev/null) || \
        echo "WARNING: could not install $PKGS; femodes.viz may not render and femodes uses SuperLU (everything else works)"
else
    echo "NOTE: optional system packages: $PKGS (Debian/Ubuntu: sudo apt-get install $PKGS); without them"
    echo "      femodes.viz does not render and sparse factorisations use SuperLU"
fi
exit 0

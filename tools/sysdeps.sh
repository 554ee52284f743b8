#!/bin/sh
# System libraries for off-screen rendering (femodes.viz: pyvista/VTK through EGL on Mesa's
# software renderer). Installed with apt when we are root on Debian/Ubuntu; otherwise we say
# exactly what to install. Everything else comes from PyPI into .venv.
if ldconfig -p 2>/dev/null | grep -q 'libEGL.so.1' && ldconfig -p 2>/dev/null | grep -q 'libgbm.so.1'; then
    exit 0
fi
PKGS="libegl1 libgl1-mesa-dri"
if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    echo "installing $PKGS (off-screen rendering for femodes.viz)"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $PKGS >/dev/null) || \
        echo "WARNING: could not install $PKGS; femodes.viz will not render (everything else works)"
else
    echo "NOTE: femodes.viz needs the system packages: $PKGS (Debian/Ubuntu: sudo apt-get install $PKGS)"
fi
exit 0

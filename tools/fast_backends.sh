#!/bin/sh
# Optional sparse direct back-ends (femodes.sparse_direct; issue 38): CHOLMOD through
# scikit-sparse and MUMPS through python-mumps, built from source against the system libraries
# that tools/sysdeps.sh installs (libsuitesparse-dev, libmumps-seq-dev, OpenBLAS). Best effort:
# a back-end whose headers are missing or whose build fails is skipped with a note, and femodes
# uses SuperLU instead (one log line). Usage: sh tools/fast_backends.sh .venv/bin/python
PY=${1:-.venv/bin/python}
BIN=$(cd "$(dirname "$PY")" && pwd)  # absolute: pip builds in a temporary directory
# python-mumps' build runs its _version.py as `#!/usr/bin/env python`: the venv's python must be
# first on PATH (Debian has no `python` command)
PATH="$BIN:$PATH"
export PATH
# scikit-sparse 0.5 does not compile against Debian 12's SuiteSparse 5.12; 0.4.16 does (~50 s)
if [ -f /usr/include/suitesparse/cholmod.h ]; then
    "$PY" -m pip install --quiet "scikit-sparse>=0.4.16,<0.5" || \
        echo "NOTE: scikit-sparse (CHOLMOD) did not build; femodes uses SuperLU for positive definite matrices"
else
    echo "NOTE: CHOLMOD headers missing (Debian/Ubuntu: apt-get install libsuitesparse-dev); skipping scikit-sparse"
fi
# python-mumps: the cp311 wheel 0.0.2 is built for numpy 1.x; 0.0.4 builds from source (~30 s)
if [ -f /usr/include/dmumps_c.h ]; then
    "$PY" -m pip install --quiet "python-mumps>=0.0.4" || \
        echo "NOTE: python-mumps (MUMPS) did not build; femodes uses SuperLU for complex and indefinite matrices"
else
    echo "NOTE: MUMPS headers missing (Debian/Ubuntu: apt-get install libmumps-seq-dev); skipping python-mumps"
fi
# PARDISO: the mkl wheel (x86-64 only; ~0.9 GB installed; proprietary licence, free to use),
# bound by femodes itself through ctypes (femodes/sparse_pardiso.py)
case "$(uname -m)" in
    x86_64|amd64)
        "$PY" -m pip install --quiet "mkl>=2024.0" || \
            echo "NOTE: the mkl wheel (PARDISO) did not install; femodes uses MUMPS or SuperLU instead" ;;
    *)
        echo "NOTE: no mkl wheel for $(uname -m); skipping PARDISO" ;;
esac
"$PY" -c "import femodes.sparse_direct as s; print('sparse direct back-ends:', ', '.join(s.available_backends()))" || true
exit 0

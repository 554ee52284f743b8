#!/bin/sh
# Rerun the round-off-sensitive tests (pytest marker `numerics`, tests/conftest.py) under other
# OpenBLAS kernels and BLAS thread counts, so that an assertion or a structural decision that
# holds only on the kernel it was written on fails here rather than on a newcomer's machine.
# Kernels: Prescott (SSE3) always, Haswell (AVX2) and SkylakeX (AVX-512) where the CPU has them.
# Usage: sh tools/blas_kernels.sh [python]   (default .venv/bin/python)
set -eu
PY=${1:-.venv/bin/python}
if [ "$(uname -m)" != "x86_64" ]; then
    echo "blas_kernels: OpenBLAS core types are x86-64 kernels; nothing to rerun on $(uname -m)"
    exit 0
fi
flags=$(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null || true)
kernels="Prescott"
case "$flags" in *" avx2"*) kernels="$kernels Haswell" ;; esac
case "$flags" in *" avx512f"*) kernels="$kernels SkylakeX" ;; esac
for k in $kernels; do
    for t in 1 2; do
        # one thread: two pytest workers; two threads: one worker (no oversubscription of 2 cores)
        if [ "$t" = 1 ]; then n="2 --dist loadscope"; else n=0; fi
        arch=$(OPENBLAS_CORETYPE=$k "$PY" -c "import numpy, threadpoolctl; print(threadpoolctl.threadpool_info()[0].get('architecture'))")
        echo "== OpenBLAS kernel $k (reported: $arch), $t BLAS thread(s)"
        OPENBLAS_CORETYPE=$k OPENBLAS_NUM_THREADS=$t OMP_NUM_THREADS=$t FEMODES_BLAS_THREADS=$t \
            "$PY" -m pytest -q -n $n -p no:cacheprovider -m "numerics and not slow"
    done
done

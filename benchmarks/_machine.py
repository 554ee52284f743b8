"""Shared by the benchmark scripts: what machine a measurement was taken on."""

from __future__ import annotations

import platform


def cpu_model(default: str = "unknown") -> str:
    """The CPU model name from /proc/cpuinfo (Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or default

"""Regenerate the gallery pictures in examples/images/: ``python examples/make_gallery.py``.

Imports every example of this folder that defines ``main(out)`` (each computes its results at
import, a few seconds to a minute each), saves its PNG into examples/images/, and renders the
animated GIF of the cantilever's nonlinear mode (needs pyvista; skipped with a message if not).
"""

import importlib.util
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
IMAGES = HERE / "images"


def load(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


MAX_PNG = 145_000


def shrink(png):
    """Keep a PNG under MAX_PNG bytes: quantize to a 256-colour palette (pillow), same pixels size."""
    png = Path(png)
    if png.stat().st_size > MAX_PNG:
        from PIL import Image

        Image.open(png).convert("RGB").quantize(256).save(png, optimize=True)
    return png


def main(names=None):
    IMAGES.mkdir(exist_ok=True)
    modules = {}
    for path in sorted(HERE.glob("*.py")):
        if path.stem == "make_gallery" or (names and path.stem not in names):
            continue
        if "def main(" not in path.read_text():
            continue
        t0 = time.perf_counter()
        modules[path.stem] = mod = load(path)
        png = shrink(mod.main(out=IMAGES))
        print(f"{path.stem:28s} {time.perf_counter() - t0:6.1f} s  {png}  {Path(png).stat().st_size / 1024:.0f} kB")
    if names and "cantilever_tip_stop" not in names:
        return
    try:
        import femodes as fm

        ex = modules.get("cantilever_tip_stop") or load(HERE / "cantilever_tip_stop.py")
        gif = fm.viz.animate(ex.backbones["CB 10 modes"][-1], ex.MODELS["CB 10 modes"],
                             IMAGES / "cantilever_mode1.gif", n_frames=16,
                             style=fm.viz.AnimationStyle(window_size=(480, 272)))
        print(f"{'animation':28s} {gif}  {Path(gif).stat().st_size / 1024:.0f} kB")
    except ImportError as err:
        print("GIF skipped:", err)


if __name__ == "__main__":
    main(sys.argv[1:] or None)

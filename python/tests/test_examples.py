"""The examples run: render.py writes a PNG that shows the mesh, compare_open3d.py prints its
table (and says so where Open3D is missing or returns no hit)."""
import os
import subprocess
import sys
import zlib

import numpy as np

from conftest import BUILD, ROOT, import_slimrt

slimrt = import_slimrt()
EXAMPLES = os.path.join(ROOT, "python", "examples")


def run(script, *args):
    env = dict(os.environ, PYTHONPATH=os.path.join(BUILD, "python"))
    return subprocess.run([sys.executable, os.path.join(EXAMPLES, script), *args], env=env,
                          capture_output=True, text=True, timeout=300, check=True).stdout


def read_png(path):
    """8-bit RGB PNG without interlace, filter type 0 on every row (as render.py writes it)."""
    data = open(path, "rb").read()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        n = int.from_bytes(data[pos:pos + 4], "big")
        kind, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if kind == b"IHDR":
            w, h = int.from_bytes(body[:4], "big"), int.from_bytes(body[4:8], "big")
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    assert (raw[:, 0] == 0).all()
    return raw[:, 1:].reshape(h, w, 3)


def test_render_example(tmp_path):
    out = str(tmp_path / "r.png")
    text = run("render.py", "canyon:32", "-o", out, "--res", "64x48")
    assert "wrote" in text
    img = read_png(out).astype(int)
    assert img.shape == (48, 64, 3)
    # The mesh fills the middle of the picture and is shaded (not one flat colour).
    centre = img[16:32, 20:44]
    assert len(np.unique(centre.reshape(-1, 3), axis=0)) > 20


def test_compare_open3d_example():
    text = run("compare_open3d.py", "terrain:16", "--rays", "2000", "--configs",
               "bvh8-tri4v,clbvh-compact,lossy-grid")
    assert "| terrain:16 | 512 | clbvh-compact |" in text
    assert "| terrain:16 | 512 | Open3D" in text
    for line in text.splitlines():
        if "| clbvh-compact |" in line:
            assert line.split("|")[5].strip() == "1.0000"  # the same hits as bvh8-tri4v

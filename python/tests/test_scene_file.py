"""slimrt.RaycastingScene.save / open: a scene file round-trips with identical hits and memory
figures, and a damaged file raises slimrt.Error naming the file."""
import numpy as np
import pytest

from conftest import icosphere, import_slimrt, random_rays

slimrt = import_slimrt()


@pytest.mark.parametrize("config", ["bvh8-tri4v", "clbvh-compact", "bvh8-pairs", "cluster"])
def test_save_open_same_hits(tmp_path, config):
    v, t = icosphere(3)
    s = slimrt.RaycastingScene(config)
    s.add_triangles(v, t)
    path = str(tmp_path / "scene.slim")
    s.save(path)
    o = slimrt.RaycastingScene.open(path)
    assert o.config == s.config
    rays = random_rays(np.random.default_rng(7), v.min(0), v.max(0), 2000)
    a, b = s.cast_rays(rays), o.cast_rays(rays)
    for k in ("t_hit", "geometry_ids", "primitive_ids", "primitive_uvs"):
        np.testing.assert_array_equal(a[k], b[k])
    assert np.isfinite(a["t_hit"]).sum() > 100
    ma, mb = s.memory(), o.memory()
    for k in ("geometry", "bvh", "other"):
        assert ma[k] == mb[k]
    sa, sb = s.stats(), o.stats()  # an opened scene reports the figures it was saved with
    for k in ("input_faces", "triangles"):
        assert sa[k] == sb[k]
    with pytest.raises(ValueError):
        o.add_triangles(v, t)


def test_damaged_file_raises(tmp_path):
    v, t = icosphere(2)
    s = slimrt.RaycastingScene("bvh8-tri4v")
    s.add_triangles(v, t)
    path = tmp_path / "scene.slim"
    s.save(str(path))
    data = bytearray(path.read_bytes())
    data[len(data) - 100] ^= 0x55
    bad = tmp_path / "bad.slim"
    bad.write_bytes(bytes(data))
    with pytest.raises(slimrt.Error, match="bad.slim.*checksum mismatch"):
        slimrt.RaycastingScene.open(str(bad))
    bad.write_bytes(bytes(data[:1000]))
    with pytest.raises(slimrt.Error, match="truncated"):
        slimrt.RaycastingScene.open(str(bad), verify_checksums=False)

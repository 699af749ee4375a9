"""3DGS PLY import and export."""
import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from schemas.ply import GaussianCloud, read_ply, write_ply
from schemas.program import InputError


def _cloud(num=50, seed=0) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(num, 4))
    return GaussianCloud(
        means=rng.normal(size=(num, 3)).astype(np.float32),
        scales=np.exp(rng.uniform(-6, 0, size=(num, 3))).astype(np.float32),
        rotations=(q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
        opacities=rng.uniform(0.01, 0.99, size=num).astype(np.float32),
        colors=rng.uniform(0, 1, size=(num, 3)).astype(np.float32))


def test_round_trip(tmp_path):
    cloud = _cloud()
    write_ply(tmp_path / "g.ply", cloud)
    back = read_ply(tmp_path / "g.ply")
    for name in ["means", "scales", "rotations", "opacities", "colors"]:
        np.testing.assert_allclose(getattr(back, name), getattr(cloud, name), rtol=2e-6, atol=2e-7, err_msg=name)


def test_written_file_has_the_standard_encoding(tmp_path):
    # Decode by hand: opacity is a logit, scales are logs, colours are SH degree-0 coefficients.
    cloud = _cloud(3)
    write_ply(tmp_path / "g.ply", cloud)
    v = PlyData.read(str(tmp_path / "g.ply"))["vertex"].data
    np.testing.assert_allclose(1 / (1 + np.exp(-v["opacity"])), cloud.opacities, rtol=1e-6)
    np.testing.assert_allclose(np.exp(v["scale_1"]), cloud.scales[:, 1], rtol=1e-6)
    np.testing.assert_allclose(0.5 + 0.28209479177387814 * v["f_dc_2"], cloud.colors[:, 2], rtol=1e-6)
    np.testing.assert_array_equal(v["rot_0"], cloud.rotations[:, 0])


def test_reads_foreign_files_with_extra_properties_and_unnormalised_rotations(tmp_path):
    # As 3DGS writes them: normals, f_rest_* (degree 3), rotations not normalised; ASCII here.
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(45)] + [
        "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    data = np.zeros(2, dtype=[(n, "f4") for n in names])
    data["x"] = [1.0, -2.0]
    data["rot_0"], data["rot_3"] = [2.0, 0.0], [0.0, 3.0]
    data["opacity"] = [0.0, 100.0]
    PlyData([PlyElement.describe(data, "vertex")], text=True).write(str(tmp_path / "foreign.ply"))
    cloud = read_ply(tmp_path / "foreign.ply")
    np.testing.assert_allclose(cloud.rotations, [[1, 0, 0, 0], [0, 0, 0, 1]])
    np.testing.assert_allclose(cloud.opacities, [0.5, 1.0])
    np.testing.assert_allclose(cloud.scales, 1.0)
    np.testing.assert_allclose(cloud.colors, 0.5)
    np.testing.assert_allclose(cloud.means[:, 0], [1.0, -2.0])


def test_bad_files_raise_input_error_naming_file_and_field(tmp_path):
    data = np.zeros(1, dtype=[(n, "f4") for n in ["x", "y", "z", "opacity"]])
    PlyData([PlyElement.describe(data, "vertex")]).write(str(tmp_path / "partial.ply"))
    with pytest.raises(InputError) as err:
        read_ply(tmp_path / "partial.ply")
    assert "partial.ply" in str(err.value) and "f_dc_0" in err.value.field

    (tmp_path / "text.ply").write_text("not a ply")
    with pytest.raises(InputError, match="text.ply"):
        read_ply(tmp_path / "text.ply")
    with pytest.raises(InputError, match="does not exist"):
        read_ply(tmp_path / "missing.ply")

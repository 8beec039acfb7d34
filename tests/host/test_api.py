"""The typed API (wavemesh.api.mesh, write_result) against the command that is a layer over it."""

import filecmp
import json
from pathlib import Path

import numpy as np
import pytest
from wavemesh import api
from wavemesh.check import check_mesh
from wavemesh.cli import main
from wavemesh.errors import WavemeshError
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.refine.native import RefineParams


def test_mesh_equals_the_command_file_for_file(tmp_path):
    np.save(tmp_path / "ball.npy", synth.ball(64))
    opts = ["--levels", "3", "--zeta", "0.5", "--metric", "vertical"]
    assert main(["mesh", str(tmp_path / "ball.npy"), *opts, "-o", str(tmp_path / "cli.obj"), "-q",
                 "--lod", str(tmp_path / "cli")]) == 0
    hf = api.load_input(str(tmp_path / "ball.npy"))
    result = api.mesh(hf, api.MeshParams(levels=3, refine=RefineParams(zeta=0.5, metric="vertical"),
                                         check_levels=True))
    written = api.write_result(result, str(tmp_path / "api.obj"), lod=str(tmp_path / "api"))
    assert filecmp.cmp(tmp_path / "cli.obj", tmp_path / "api.obj", shallow=False)
    assert sorted(Path(p).name for p in written) == sorted(p.name for p in (tmp_path / "cli").iterdir())
    # the result's own content: the last level is the mesh, within zeta, every level proper and measured
    assert result.level_meshes[-1][1] is result.mesh and result.levels == 3
    assert result.bound_met and result.exit_status == 0 and result.bound_warning() is None
    assert result.e_max == result.errors.e_max_vertical <= 0.5 + 1e-9
    assert all(check_mesh(m).valid for _, m in result.level_meshes)
    assert [r["level"] for r in result.rows] == [lv for lv, _ in result.level_meshes]
    assert all("e_max" in r for r in result.rows)  # check_levels: measured rows


def test_initial_only_and_the_report(tmp_path):
    hf = from_array(synth.f2())
    result = api.mesh(hf, api.MeshParams(levels=4, initial_only=True))
    assert (result.mesh.n_vertices, result.mesh.n_triangles) == (153, 256)  # as test_cli's
    assert result.refine_params is None and result.rows == [] and result.exit_status == 0
    api.write_result(result, str(tmp_path / "m.ply"), report=str(tmp_path / "r.json"))
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["parameters"]["stage"] == "initial" and report["output"] == str(tmp_path / "m.ply")


def test_a_budget_above_zeta_is_a_status_not_an_error():
    hf = from_array(synth.ball(64))
    result = api.mesh(hf, api.MeshParams(levels=3, refine=RefineParams(zeta=0.01, max_triangles=120)))
    assert not result.bound_met and result.exit_status == api.BOUND_NOT_MET
    assert "--max-triangles 120" in result.bound_warning()


@pytest.mark.parametrize("params,what", [(api.MeshParams(levels=0), "--levels 0"),
                                         (api.MeshParams(tau=float("nan")), "--tau nan")])
def test_bad_parameters_are_one_error(params, what):
    with pytest.raises(WavemeshError, match=what):
        api.mesh(from_array(synth.f2()), params)

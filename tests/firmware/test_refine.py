"""The refiner from Python: random fields of random sizes with random parameters always give a proper
triangulation (wavemesh.check.check_mesh) with E_max <= zeta (wavemesh.check.mesh_errors, measured
independently in floating point); the budget; determinism; Ball, Box and a real DEM."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from wavemesh import api
from wavemesh.check import check_mesh, mesh_errors
from wavemesh.io import synth
from wavemesh.io.heightfield import from_array
from wavemesh.refine import native

EPS = 1e-9  # the float metric's own rounding


def field(draw_kind, rng, w, h):
    x, y = np.meshgrid(np.arange(w), np.arange(h))
    if draw_kind == "noise":
        return rng.integers(0, 1000, size=(h, w)).astype(np.float64)
    if draw_kind == "steps":
        return np.where(x + 2 * y > (w + h) // 2, 500.0,
                        0.0) + np.where((x - w / 3) ** 2 + (y - h / 2) ** 2 < w, 300, 0)
    if draw_kind == "smooth":
        return np.round(200 * np.sin(x / 5.0) * np.cos(y / 7.0) + 0.3 * x * y)
    if draw_kind == "float":  # lossy quantisation
        return np.sin(x / 3.0) + 0.01 * rng.normal(size=(h, w))
    return np.zeros((h, w))


def assert_bound(hf, rjob):
    p = rjob.params
    final = rjob.output.final
    assert final.stats["over"] == 0
    if hf.lossless:
        rep = mesh_errors(final.mesh, hf.values)
        e = rep.e_max_normal if p.metric == "normal" else rep.e_max_vertical
        assert e <= p.zeta + EPS * max(1, p.zeta), (e, p.zeta)
    else:
        # on the samples the firmware saw, with the zeta it was given; vertically also on the input
        quantised = hf.offset + hf.scale * hf.samples.astype(np.float64)
        rep = mesh_errors(final.mesh, quantised)
        e = rep.e_max_normal if p.metric == "normal" else rep.e_max_vertical
        assert e <= rjob.zeta_used + EPS * max(1, p.zeta), (e, rjob.zeta_used)
        if p.metric == "vertical" and p.zeta >= 2 * hf.max_quantisation_error:
            assert mesh_errors(final.mesh, hf.values).e_max_vertical <= p.zeta + EPS * max(1, p.zeta)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    w=st.integers(2, 70), h=st.integers(2, 70), kind=st.sampled_from(["noise", "steps", "smooth", "float",
                                                                      "flat"]),
    seed=st.integers(0, 2**31), levels=st.integers(1, 6), zeta=st.floats(0, 80),
    metric=st.sampled_from(["normal", "vertical"]), neighbourhood=st.sampled_from(["face", "vertex"]),
    iterations=st.integers(0, 3), alpha=st.floats(0, 1), delta_p=st.floats(0.5, 0.99),
    delta_v=st.floats(0, 4), delta_d=st.sampled_from([0.0, 0.1, 1.0, 100.0]),
)
def test_random_fields_give_proper_meshes_within_zeta(w, h, kind, seed, levels, zeta, metric, neighbourhood,
                                                      iterations, alpha, delta_p, delta_v, delta_d):
    rng = np.random.default_rng(seed)
    hf = from_array(field(kind, rng, w, h))
    if kind == "float":
        zeta = zeta / 100
    params = native.RefineParams(zeta=zeta, metric=metric, neighbourhood=neighbourhood, iterations=iterations,
                                 alpha=alpha, delta_p=delta_p, delta_v=delta_v, delta_d=delta_d)
    rjob = api.refine(hf, levels, None, params)  # checks every level with check_mesh
    assert len(rjob.output.levels) == max(levels, 2)  # M-1 .. 0, and the error bound alone when M = 1
    assert [lv.level for lv in rjob.output.levels][-1] == 0
    assert_bound(hf, rjob)


def test_budget_stops_early_and_says_so():
    hf = from_array(synth.box(64))
    budget = api.triangulate(hf, 3).mesh.n_triangles + 41  # the initial mesh is never cut down
    # without the reduction, which would keep this flat-faced box far below the budget
    rjob = api.refine(hf, 3, None, native.RefineParams(zeta=0.5, max_triangles=budget, reduce=False))
    final = rjob.output.final
    assert check_mesh(final.mesh).valid
    assert budget - 2 <= final.mesh.n_triangles <= budget
    assert final.stats["budget_hit"] == 1 and not rjob.bound_met
    assert final.stats["over"] > 0
    assert all(lv.mesh.n_triangles <= budget for lv in rjob.output.levels)


def test_small_capacity_is_an_error_or_grows():
    hf = from_array(synth.box(64))
    with pytest.raises(native.WavemeshError, match="capacity"):
        api.refine(hf, 3, None, native.RefineParams(zeta=0.5, capacity=40))
    # the default storage starts small and grows: the same mesh as with room for everything
    small = api.refine(hf, 3, None, native.RefineParams(zeta=0.0))
    big = api.refine(hf, 3, None, native.RefineParams(zeta=0.0, capacity=2 * 63 * 63))
    assert small.mesh.same_as(big.mesh)


def test_same_input_same_mesh():
    hf = from_array(synth.ball(96))
    runs = [api.refine(hf, 4, None, native.RefineParams(zeta=0.5, iterations=3)) for _ in range(2)]
    for a, b in zip(runs[0].output.levels, runs[1].output.levels, strict=True):
        np.testing.assert_array_equal(a.mesh.xy, b.mesh.xy)
        np.testing.assert_array_equal(a.mesh.tris, b.mesh.tris)
        assert a.stats == b.stats


def jacksboro():
    import matplotlib.cbook as cbook

    with np.load(cbook.get_sample_data("jacksboro_fault_dem.npz", asfileobj=False)) as z:
        return z["elevation"]


@pytest.mark.parametrize("metric", ["normal", "vertical"])
@pytest.mark.parametrize("name,zeta,levels,k", [("ball", 1.0, 5, 2), ("box", 1.0, 5, 2), ("jacksboro", 2.0,
                                                                                          5, 3)])
def test_data_sets_meet_zeta_at_level_0(name, zeta, levels, k, metric):
    values = jacksboro() if name == "jacksboro" else synth.make(name)
    if name == "jacksboro" and metric == "vertical":
        zeta = 10.0  # 2 m vertically needs nearly every sample of this rough DEM
    hf = from_array(values)
    rjob = api.refine(hf, levels, None, native.RefineParams(zeta=zeta, metric=metric, iterations=k))
    counts = [lv.mesh.n_triangles for lv in rjob.output.levels]
    # The levels refine (a level's reduction, 3(b), can remove more than it adds once the levels above met
    # zeta); level 0 ends with the decimation, which only removes.
    levels_stats = [lv.stats for lv in rjob.output.levels[1:]]
    assert all(st["edge_splits"] + st["ternary_splits"] + st["moves"] > 0 for st in levels_stats[:2])
    assert counts[0] < max(counts)
    final = rjob.output.final.stats
    assert final["removals"] > 0 and final["triangles"] == counts[-1]
    assert_bound(hf, rjob)

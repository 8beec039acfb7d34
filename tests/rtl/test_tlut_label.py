"""rtl/tlut_label.v (the dominant-coefficient labeller) against wavemesh.model.label (bench:
tlut_label_tb.py)."""

import numpy as np
from tlut_label_tb import expected_labels, random_details
from wavemesh.harness.rtl_runner import RTL, run


def test_bench_expectations_cover_every_label_and_demotion():
    d = random_details(np.random.default_rng(0), 4000)
    labels = expected_labels(d, 40).reshape(-1, 4)
    assert set(labels[:, 0].tolist()) == set(range(7))  # no demotion: F f V v H h D
    assert not np.isin(labels[:, 1], [2, 3, 6]).any()  # narrow: no V, v, D
    assert not np.isin(labels[:, 2], [4, 5, 6]).any()  # low: no H, h, D
    assert set(labels[:, 3].tolist()) == {0, 1}  # both: flat only


def test_tlut_label():
    run("tlut_label", [RTL / "tlut_label.v"], "tlut_label_tb", parameters={"USER_WIDTH": 16})

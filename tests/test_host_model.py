"""The host's replay of the estimator rules and the fault-injection planner (no C needed)."""

from __future__ import annotations

import numpy as np
import pytest

from fleetlab.data import features_int as fi
from fleetlab.host_tools.verify import stream_faults as faults
from fleetlab.host_tools.verify.compare import EstimatorModel, compare_status, compare_windows
from fleetlab.host_tools.wire.items import WireItem
from fleetlab.host_tools.wire.dbc import Frame, StatusReport, WindowEstimate, control_frame, telemetry_frames


def _samples(n_windows: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.array([800, 1500, 20, -30, 9700, 100, -200])
    walk = np.cumsum(rng.integers(-40, 41, size=(n_windows * 100, 7)), axis=0)
    return np.clip(base + walk, -32768, 32767).astype(np.int16)


def _replay(items: list[WireItem]) -> EstimatorModel:
    m = EstimatorModel()
    for i, it in enumerate(items):
        m.feed(it, i)
    return m


def test_clean_stream_gives_the_featuriser_windows_and_no_loss():
    x = _samples(12)
    plan = faults.plan_telemetry(x, [], 0.0, seed=0)
    assert len(plan.segments) == 1
    m = _replay(plan.segments[0].items)
    ref = fi.featurise_int(x)
    wins = m.windows()
    assert [w.window_index for w in wins] == list(range(12))
    assert np.array_equal(np.stack([w.feat_q for w in wins]), ref.features)
    c = m.status_snapshot()
    assert c.frames_received == len(plan.segments[0].items) == 12 * 300 + 2
    assert (c.frames_rejected, c.samples_dropped, c.windows_flagged, c.windows_done) == (0, 0, 0, 12)
    # each window is emitted by its own last sample's last frame
    assert [w.trigger_item for w in wins] == [1 + 300 * (k + 1) - 1 for k in range(12)]


@pytest.mark.parametrize("kind", [k for k in faults.KINDS if k != "restart"])
def test_each_fault_kind_has_its_predicted_effect(kind):
    x = _samples(40, seed=3)
    plan = faults.plan_telemetry(x, [kind], 0.3, seed=5)
    assert plan.faults and all(f.kind == kind for f in plan.faults)
    m = _replay(plan.segments[0].items)
    c = m.status_snapshot()
    r, d, flag = faults.EFFECTS[kind]
    assert c.frames_rejected == r * len(plan.faults)
    assert c.samples_dropped == d * len(plan.faults)
    assert c.windows_flagged == (len(plan.faults) if flag else 0)
    clean = fi.featurise_int(x)
    wins = {w.window_index: w for w in m.windows()}
    assert len(wins) == 40  # no window lost
    faulty = {f.window for f in plan.faults}
    for w, ew in wins.items():
        if w in faulty and flag:
            assert ew.flags & fi.FLAG_GAP and ew.n_samples == 99
        else:  # every other window (and the windows of harmless faults) stays bit-exact
            assert ew.flags == 0 and np.array_equal(ew.feat_q, clean.features[w])


def test_restart_splits_lifetimes_and_counts_the_lost_window():
    x = _samples(30, seed=1)
    plan = faults.plan_telemetry(x, ["restart"], 0.0, seed=0, restart_every=10)
    assert len(plan.segments) == 3 and [s.ends_with_restart for s in plan.segments] == [True, True, False]
    assert sum(s.windows_lost_to_restart for s in plan.segments) == 2
    # every sample of the cut windows is either sent before the kill or skipped by the host
    sent = [s.n_source_units for s in plan.segments]
    assert sum(sent) + sum(s.samples_skipped_by_restart for s in plan.segments) == 30 * 100
    assert all(0 < s.samples_skipped_by_restart < 100 for s in plan.segments[:2])
    got = [_replay(s.items).windows() for s in plan.segments]
    assert [len(w) for w in got] == [10, 9, 9]
    # after a restart the grid restarts at the next window of the host's grid
    clean = fi.featurise_int(x).features
    assert np.array_equal(got[1][0].feat_q, clean[11])
    for s in plan.segments:
        assert s.items[0].frame == control_frame(1) and s.items[-1].frame == control_frame(2)


def test_all_kinds_at_high_rate_keep_counts_consistent():
    x = _samples(60, seed=2)
    kinds = faults.parse_kinds("all", "serial")
    plan = faults.plan_telemetry(x, kinds, 0.5, seed=9)
    assert {f.kind for f in plan.faults} == set(kinds)
    for si, seg in enumerate(plan.segments):
        c = _replay(seg.items).status_snapshot()
        fs = [f for f in plan.faults if f.segment == si]
        assert c.frames_rejected == sum(f.frames_rejected for f in fs)
        assert c.samples_dropped == sum(f.samples_dropped for f in fs)


def test_parse_kinds_refuses_what_a_link_cannot_carry():
    assert "bad_crc" not in faults.parse_kinds("all", "inproc")
    with pytest.raises(ValueError, match="bad_crc"):
        faults.parse_kinds("bad_crc", "inproc")
    with pytest.raises(ValueError, match="unknown fault kind"):
        faults.parse_kinds("bit_flip", "serial")
    with pytest.raises(ValueError, match="cannot be carried"):
        faults.parse_kinds("dropped_sample", "serial", features_source=True)


def test_late_duplicate_and_incomplete_frames_follow_the_rules():
    x = _samples(2)
    fr = [telemetry_frames(i, x[i]) for i in range(200)]
    items = [WireItem(f) for f in fr[0]]
    items += [WireItem(fr[1][0]), WireItem(fr[1][1])]  # sample 1 incomplete ...
    items += [WireItem(f) for f in fr[2]]  # ... abandoned when sample 2 starts
    items += [WireItem(fr[1][2])]  # its last frame arrives late
    items += [WireItem(fr[2][0])]  # duplicate of a completed sample
    items += [WireItem(Frame(0x100, b"\x00"))]  # wrong length
    items += [WireItem(Frame(0x0F0, bytes([9, 0])))]  # unknown command
    for i in range(3, 200):
        items += [WireItem(f) for f in fr[i]]
    m = _replay(items)
    c = m.status_snapshot()
    assert c.frames_rejected == 4 and c.samples_dropped == 1 and c.windows_flagged == 1
    assert m.rejected_by_reason == {"late": 1, "duplicate": 1, "wrong_length": 1, "bad_command": 1}
    w0 = m.windows()[0]
    assert w0.n_samples == 99 and w0.flags == fi.FLAG_GAP


def test_compare_windows_flags_every_difference():
    x = _samples(3)
    plan = faults.plan_telemetry(x, [], 0.0, seed=0)
    exp = _replay(plan.segments[0].items).windows()

    def q_ref(q):
        return np.asarray(q, np.int64)[:, :3] * 10, np.zeros(len(q), np.int64)

    def est(w, **kw):
        logits = tuple(int(v) * 10 for v in w.feat_q[:3])
        e = WindowEstimate(w.window_counter, int(np.argmax(logits)), 0, 0, 100, 0, logits)
        for k, v in kw.items():
            setattr(e, k, v)
        return e

    good = [est(w) for w in exp]
    verdicts, extra = compare_windows(exp, good, q_ref)
    assert all(v.bit_exact for v in verdicts) and not extra
    bad = [est(exp[0]), est(exp[1], logits=(1, 2, 3)), est(exp[2], n_samples=99)]
    verdicts, _ = compare_windows(exp, bad, q_ref)
    assert [v.bit_exact for v in verdicts] == [True, False, False]
    verdicts, _ = compare_windows(exp, good[:2], q_ref)
    assert verdicts[2].problems == ["missing"]
    c = _replay(plan.segments[0].items).status_snapshot()
    rep = StatusReport(0, 0, c.windows_done, c.frames_received, 0, 0, 0)
    assert compare_status(c, rep) == []
    rep.frames_received -= 1
    assert compare_status(c, rep) and compare_status(c, None)


def test_control_reset_restarts_the_grid_and_keeps_counters():
    x = _samples(5, seed=7)
    fr = [telemetry_frames(i, x[i]) for i in range(500)]
    items = [WireItem(f) for i in range(250) for f in fr[i]]  # 2.5 windows
    items.append(WireItem(control_frame(1)))  # the open half window is discarded
    items += [WireItem(f) for i in range(300, 500) for f in fr[i] if i != 450]  # one sample missing
    m = _replay(items)
    wins = m.windows()
    assert [w.window_index for w in wins] == [0, 1, 0, 1]  # the new grid starts at sample 300
    clean = fi.featurise_int(x).features
    assert np.array_equal(wins[2].feat_q, clean[3]) and wins[2].flags == 0
    assert wins[3].n_samples == 99 and wins[3].flags == fi.FLAG_GAP
    c = m.status_snapshot()
    assert (c.samples_dropped, c.windows_flagged, c.windows_done) == (1, 1, 4)
    assert c.frames_received == len(items) and c.frames_rejected == 0

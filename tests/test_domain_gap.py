"""The simulated Earth analog and Moon differ enough that an Earth-trained SN-S is near chance on the Moon."""

from __future__ import annotations

import numpy as np

from fleetlab.data.dataset import EARTH, TARGET
from fleetlab.evaluation.domain_gap import earth_to_moon_gap
from fleetlab.data.simulator.engine import simulate_batch
from fleetlab.data.simulator.scenario import scenario_specs


def test_earth_trained_sn_s_is_near_chance_on_the_moon():
    entries = [(role, name, spec) for role, name, spec in scenario_specs(1, 1.0) if role in (EARTH, TARGET)]
    traces = simulate_batch([spec for _, _, spec in entries])
    data = [(role, name, trace) for (role, name, _), trace in zip(entries, traces)]
    gap = earth_to_moon_gap(data, seed=0, steps=1200)
    print(f"balanced accuracy: held-out Earth {gap.earth_heldout_bacc:.3f}, target Moon {gap.target_moon_bacc:.3f}")
    assert gap.n_train > 1000 and gap.n_earth_heldout > 400 and gap.n_target > 1300
    # Since the realism redesign (issue 17) every traverse crosses its own site soils, so an Earth model
    # does not carry over even to unseen Earth traverses as it once did (held-out Earth was >= 0.75).
    # What holds, as on the real files (Earth expert zero-shot 0.40): on the Moon it is near chance.
    assert gap.target_moon_bacc < 0.45
    # And the Moon is not simply unlearnable: the lunar data has every class in numbers.
    target_labels = np.concatenate([t.windows().label for role, _, t in data if role == TARGET])
    assert np.bincount(target_labels, minlength=3).min() > 100

"""The built-in fleet scenario, mirroring the Fleet-to-Lab setting.

* `earth`: the target rover in an Earth analog facility (g = 9.81, firm analog
  sand with loose patches, gentle slopes) - mostly low slip.
* `fleet_scout`, `fleet_hauler`: two fleet rovers on three lunar terrains
  (g = 1.62) - more moderate and high slip.
* `target`: the target rover on three lunar terrains with a soil no fleet rover
  has driven on, split over several traverses so that calibration and test can
  come from different traverses.

`write_scenario` writes one Fleet-To-Lab CSV per traverse plus `dataset.json`.
`fleet` replaces the two fleet rovers by any built-in rovers (the target's sister
`leo` included) driving the same lunar terrains; the Earth and target traverses
stay byte-identical whatever the fleet, so scenarios can be compared run for run.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from ..contracts import DEFAULT_RATE_HZ, RAW_CHANNELS
from ..csvio import WindowTable, write_windows_csv
from ..dataset import EARTH, FLEET_PREFIX, TARGET, write_manifest
from ..features import WindowSpec
from ..label_noise import VO_LABEL_COLUMNS, vo_labels
from .engine import ACCEL_LINEAR, Trace, TraverseSpec, simulate_batch
from .rovers import GRAVITY_EARTH, GRAVITY_MOON, ROVERS
from .terrain import TERRAINS
from ...errors import InputError

GENERATOR = "fleetlab.data.simulator/1"


@dataclass(frozen=True)
class TraverseGroup:
    role: str
    rover: str
    terrains: tuple[str, ...]  # assigned to traverses in turn
    gravity: float
    n_traverses: int
    duration_s: float  # per traverse at scale 1


SCENARIO: tuple[TraverseGroup, ...] = (
    TraverseGroup(EARTH, "leo", ("analog_hall",), GRAVITY_EARTH, 10, 402.0),
    TraverseGroup(FLEET_PREFIX + "scout", "scout", ("mare_plain", "highland_slope", "crater_rim"), GRAVITY_MOON, 10, 382.0),
    TraverseGroup(FLEET_PREFIX + "hauler", "hauler", ("mare_plain", "highland_slope", "crater_rim"), GRAVITY_MOON, 10, 382.0),
    TraverseGroup(TARGET, "leo", ("polar_crater", "ejecta_field", "rille_wall"), GRAVITY_MOON, 8, 352.0),
)


DEFAULT_FLEET: tuple[str, ...] = tuple(g.rover for g in SCENARIO if g.role.startswith(FLEET_PREFIX))


def traverse_seed(seed: int, group: int, traverse: int) -> int:
    """Independent, reproducible seed of one traverse of the scenario."""
    return int(np.random.SeedSequence([seed, group, traverse]).generate_state(1)[0])


def scenario_groups(fleet: tuple[str, ...] | None = None) -> list[tuple[int, TraverseGroup]]:
    """(seed group id, group) of the scenario with the given fleet rovers (default: scout, hauler).

    The Earth and target groups keep their ids, and fleet rover i takes the id the default
    scenario gives fleet slot i (1, 2, then 4, 5, ...), so the same seed draws the same
    Earth and target traverses whatever the fleet.
    """
    fleet = DEFAULT_FLEET if fleet is None else tuple(fleet)
    unknown = [r for r in fleet if r not in ROVERS]
    if unknown or not fleet:
        raise InputError(f"fleet rovers must be one or more of {', '.join(ROVERS)}; got {', '.join(fleet) or 'none'}")
    if len(set(fleet)) != len(fleet):
        raise InputError(f"each fleet rover may appear once (one role per rover), got {', '.join(fleet)}")
    template = next(g for g in SCENARIO if g.role.startswith(FLEET_PREFIX))
    fixed = [(gi, g) for gi, g in enumerate(SCENARIO) if not g.role.startswith(FLEET_PREFIX)]
    free_ids = [gi for gi, g in enumerate(SCENARIO) if g.role.startswith(FLEET_PREFIX)]
    free_ids += list(range(len(SCENARIO), len(SCENARIO) + len(fleet)))
    members = [(free_ids[i], dataclasses.replace(template, role=FLEET_PREFIX + r, rover=r)) for i, r in enumerate(fleet)]
    return fixed[:1] + members + fixed[1:]  # earth, fleet..., target


def scenario_specs(seed: int, scale: float = 1.0, fleet: tuple[str, ...] | None = None) -> list[tuple[str, str, TraverseSpec]]:
    """(role, file stem, spec) of every traverse; `scale` shrinks the number and length of traverses."""
    if not (0.0 < scale <= 10.0):
        raise InputError(f"scale must be in (0, 10], got {scale}")
    out = []
    for gi, grp in scenario_groups(fleet):
        n = max(2, round(grp.n_traverses * math.sqrt(scale)))
        duration = max(20.0, grp.duration_s * scale * grp.n_traverses / n)
        for t in range(n):
            terrain = grp.terrains[t % len(grp.terrains)]
            stem = f"{grp.role}_{terrain}_{t + 1:02d}"
            out.append((grp.role, stem, TraverseSpec.make(grp.rover, terrain, grp.gravity, duration,
                                                         traverse_seed(seed, gi, t))))
    return out


def scenario_traces(seed: int, scale: float = 1.0, rate_hz: float = DEFAULT_RATE_HZ,
                    progress: bool = False, fleet: tuple[str, ...] | None = None,
                    accel: str = ACCEL_LINEAR) -> list[tuple[str, str, Trace]]:
    """Simulate the built-in scenario: (role, name, Trace) per traverse."""
    entries = scenario_specs(seed, scale, fleet)
    specs = [spec for _, _, spec in entries]
    total = sum(int(round(s.duration_s * rate_hz)) for s in specs)
    with tqdm(total=total, desc="simulating", unit="sample", unit_scale=True, disable=not progress) as bar:
        traces = simulate_batch(specs, rate_hz, progress=bar, accel=accel)
    return [(role, name, trace) for (role, name, _), trace in zip(entries, traces)]


def write_scenario(out_dir: Path | str, seed: int, scale: float = 1.0, rate_hz: float = DEFAULT_RATE_HZ,
                   raw: bool = False, progress: bool = False, fleet: tuple[str, ...] | None = None,
                   accel: str = ACCEL_LINEAR, bag: Path | str | None = None, bag_storage: str = "mcap",
                   labels: str = "exact", csv_logs: Path | str | None = None) -> Path:
    """Write one window CSV per traverse and dataset.json into out_dir (created); returns out_dir.

    With `raw`, also one .npz per traverse with the raw samples and distance increments.
    With `bag`, also one rosbag2 per traverse in that folder, and the rover profiles beside them
    (`simulator.bag`). With `csv_logs`, also each traverse as time-series CSV logs without attitude, one
    folder per rover profile, with the profiles beside them (`simulator.csv_logs`). With `labels` 'vo', also NAME.vo_labels.csv beside each traverse's CSV: every window's
    slip and class as a rover's visual odometry would measure them (`label_noise.vo_labels`), next to the true ones.
    """
    if labels not in LABEL_SOURCES:
        raise InputError(f"labels {labels!r}: one of {', '.join(LABEL_SOURCES)}")
    WindowSpec.for_rate(rate_hz)  # refuse a rate too low for 2 s windows before simulating
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, dict] = {}
    for index, (role, name, trace) in enumerate(scenario_traces(seed, scale, rate_hz, progress, fleet, accel)):
        table = WindowTable.from_windows(trace.windows())
        write_windows_csv(out / f"{name}.csv", table)
        entry = {"role": role, **{k: trace.meta[k] for k in ("rover", "terrain", "soils", "gravity", "seed")},
                 "duration_s": trace.meta["duration_s"], "windows": len(table),
                 "class_counts": table.class_counts()}
        if labels == "vo":
            entry["vo_labels"] = _write_vo_labels(out / f"{name}.vo_labels.csv", table, trace.meta["terrain"],
                                                  np.random.default_rng([seed, index, VO_STREAM]))
        if raw:
            np.savez_compressed(out / f"{name}.npz", samples=trace.samples, d_actual_step=trace.d_actual_step,
                                d_cmd_step=trace.d_cmd_step, rate_hz=trace.rate_hz,
                                channels=np.array(RAW_CHANNELS), **{f"truth_{k}": v for k, v in trace.truth.items()})
            entry["raw"] = f"{name}.npz"
        if bag is not None:
            from .bag import profile_name, profile_toml, write_traverse_bag

            Path(bag).mkdir(parents=True, exist_ok=True)
            write_traverse_bag(Path(bag) / name, trace, trace.meta["rover"], trace.meta["gravity"], bag_storage)
            profile = Path(bag) / profile_name(trace.meta["rover"], trace.meta["gravity"])
            profile.write_text(profile_toml(trace.meta["rover"], trace.meta["gravity"]))
            entry["bag"] = {"path": name, "profile": profile.name}
        if csv_logs is not None:
            from .csv_logs import folder_name, write_traverse_csv_logs

            profile = write_traverse_csv_logs(Path(csv_logs), name, trace, trace.meta["rover"], trace.meta["gravity"])
            entry["csv_logs"] = {"folder": folder_name(trace.meta["rover"], trace.meta["gravity"]),
                                 "suffix": name, "profile": profile.name}
        files[f"{name}.csv"] = entry
    write_manifest(out, files, {"generator": GENERATOR, "seed": seed, "scale": scale, "rate_hz": rate_hz,
                                "fleet": list(DEFAULT_FLEET if fleet is None else fleet), "accel": accel})
    return out


LABEL_SOURCES = ("exact", "vo")
VO_STREAM = 0x564F  # the VO labels' own random stream, apart from the traverses'


def low_texture(terrain: str) -> bool:
    """Terrain where visual odometry loses track more often: smooth ground without rocks (roughness <= 1)
    gives its cameras few features to follow."""
    return TERRAINS[terrain].roughness <= 1.0


def _write_vo_labels(path: Path, table: WindowTable, terrain: str, rng: np.random.Generator) -> dict:
    cols = vo_labels(table.d_actual, table.d_commanded, table.duration_s, rng, low_texture(terrain))
    ints = {"slip_class", "slip_class_vo", "vo_dropout"}
    with open(path, "w", newline="", encoding="utf-8") as fh:
        fh.write(",".join(VO_LABEL_COLUMNS) + "\r\n")
        for row in zip(*(cols[c] for c in VO_LABEL_COLUMNS)):
            fh.write(",".join(str(int(v)) if c in ints else repr(float(v)) for c, v in zip(VO_LABEL_COLUMNS, row))
                     + "\r\n")
    wrong = int((cols["slip_class"] != cols["slip_class_vo"]).sum())
    return {"file": path.name, "low_texture": low_texture(terrain), "wrong": wrong,
            "dropouts": int(cols["vo_dropout"].sum())}

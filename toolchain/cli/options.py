"""Option groups shared by several subcommands. Defaults come from the library's own
config objects (AcoMergeConfig, the expert training constants), never from literals here."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..compute import AUTO_THREADS, MAX_THREADS, resolve_device
from ..data.splits import PROTOCOLS
from ..fusion.acomerge import AcoMergeConfig
from ..models.mlp import ARCHS, MAX_HIDDEN_LAYERS, MAX_UNITS, MIN_UNITS, canonical_arch
from ..models.train import EXPERT_EPOCHS, FC_RATE
from ..errors import InputError

ACO = AcoMergeConfig()  # the paper's AcoMerge defaults: the one source of every search default below


def data_dir(p: argparse.ArgumentParser, help: str = "dataset folder: made by 'fleetlab simulate' or 'fleetlab data "
             "import' (dataset.json) or the original Fleet-To-Lab CSVs; or a roles .toml file naming several "
             "folders and their roles (docs/your_rover.md)") -> None:
    p.add_argument("--data", required=True, type=Path, metavar="DIR", help=help)


def arch(p: argparse.ArgumentParser, default: str = "sn-s") -> None:
    """The one --arch option (training, fuse, evaluate, export, bench fusion): a name or hidden sizes."""

    def parse(text: str) -> str:
        try:
            return canonical_arch(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    p.add_argument("--arch", default=default, type=parse, metavar="ARCH",
                   help=f"network architecture: {', '.join(ARCHS)} ({'; '.join(f'{k} = {list(v)}' for k, v in ARCHS.items())}), "
                   f"or hidden sizes such as 64,32 (1-{MAX_HIDDEN_LAYERS} layers of {MIN_UNITS}-{MAX_UNITS} units; "
                   f"default: {default})")


def protocol(p: argparse.ArgumentParser) -> None:
    p.add_argument("--protocol", choices=PROTOCOLS, default="paper",
                   help="calibration draw: 'paper' = stratified random rows (as in the paper), "
                   "'traverse' = leakage-free, calibration and test from different traverses (default: paper)")


def seed(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument("--seed", type=int, default=0, help=f"seed of {what} (default: 0)")


def epochs(p: argparse.ArgumentParser, what: str = "the experts") -> None:
    p.add_argument("--epochs", type=int, default=EXPERT_EPOCHS,
                   help=f"training epochs of {what} (default: {EXPERT_EPOCHS})")


def search_budget(p: argparse.ArgumentParser, generations_help: str, copies: bool = False) -> None:
    """--generations, --ants, --sigma (and --copies): AcoMerge's budget and its expert buffer."""
    p.add_argument("--generations", type=int, default=ACO.generations,
                   help=f"{generations_help} (default: {ACO.generations})")
    p.add_argument("--ants", type=int, default=ACO.n_ants, help=f"AcoMerge ants per generation (default: {ACO.n_ants})")
    if copies:
        p.add_argument("--copies", type=int, default=ACO.copies,
                       help=f"perturbed copies per expert in the buffer (default: {ACO.copies})")
    p.add_argument("--sigma", type=float, default=ACO.sigma,
                   help=f"std of the Gaussian-perturbed expert copies in the buffer (default: {ACO.sigma:g}, the "
                   "paper's value; the reference code used 0.005)")


def noise_rate(p: argparse.ArgumentParser) -> None:
    """--noise-rate: the adjacent label-noise rate that the forward-corrected methods assume (issue 46)."""
    p.add_argument("--noise-rate", type=float, default=FC_RATE, metavar="EPS",
                   help="the share of D_Cal's labels that the forward-corrected methods (acomerge-fc, earth-ft-fc, "
                        "acomerge-robust-fc) assume a neighbouring class took, e.g. from the visual odometry's "
                        f"measured accuracy; other methods ignore it (default: {FC_RATE})")


def threads(p: argparse.ArgumentParser) -> None:
    p.add_argument("--threads", type=int, default=AUTO_THREADS,
                   help=f"threads for training and for batched search evaluation (default: {AUTO_THREADS} = chosen "
                        f"when the work starts: the cores no other process keeps busy then, up to {MAX_THREADS})")


def device(p: argparse.ArgumentParser) -> None:
    p.add_argument("--device", default="cpu", metavar="cpu|cuda|auto",
                   help="where AcoMerge searches and the source models train: cpu (the reference, default), cuda or "
                        "cuda:N (a GPU; results differ from the CPU's in float rounding and random stream), auto "
                        "(cuda when one is present)")
    p.add_argument("--rng", default="device", choices=("device", "host"),
                   help="where a GPU search draws its random numbers: device (fast, the default; another stream "
                        "than the CPU's) or host (the CPU reference's generators, uploaded each generation: the "
                        "GPU then differs from --device cpu by float rounding only, and the source models train on the "
                        "CPU; slower). No effect on the CPU")


def resolved_device(args: argparse.Namespace) -> str:
    """--device as AcoMergeConfig takes it ('cpu', 'cuda', 'cuda:N'); a one-line error without a GPU."""
    return str(resolve_device(args.device))


def jobs(p: argparse.ArgumentParser) -> None:
    p.add_argument("--jobs", type=int, default=1, help="parallel local worker processes (default: 1)")


def json_file(p: argparse.ArgumentParser, what: str = "the results") -> None:
    p.add_argument("--json", type=Path, metavar="FILE", help=f"write {what} as JSON")


def no_progress(p: argparse.ArgumentParser) -> None:
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def at_least_one(args: argparse.Namespace, *names: str) -> None:
    """Refuse counts below 1 with the option's own spelling."""
    for name in names:
        if getattr(args, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")

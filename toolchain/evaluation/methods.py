"""Which registered fusion methods an evaluation compares, and how the table groups them.

The methods themselves live in `fleetlab.fusion` (`registry`, `methods`); this module only
reads the registry, so a newly registered method appears in `fleetlab evaluate` as is.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping

from ..fusion import registry
from ..errors import InputError

BUFFER_ABLATION, FLEET_ABLATION = registry.ABLATION_GROUPS
# Groups that are shown but never ranked best/second.
UNRANKED_GROUPS = ("Ablation", *registry.ABLATION_GROUPS)


def selectable() -> tuple[str, ...]:
    """Methods `--methods` accepts, in table order (every registered method but the ablation switches')."""
    return registry.selectable()


def default_methods() -> tuple[str, ...]:
    """What `--methods all` (and no --methods) runs: the selectable methods but the opt-in groups'."""
    return registry.default_methods()


def needs_label_probs(name: str) -> bool:
    """Whether method `name` fits on each label's class probabilities (registry.MethodSpec)."""
    return registry.get(name).needs_label_probs


def buffer_methods() -> tuple[str, ...]:
    return registry.in_group(BUFFER_ABLATION)


def fleet_methods() -> tuple[str, ...]:
    return registry.in_group(FLEET_ABLATION)


def table_groups() -> dict[str, tuple[str, ...]]:
    """Group -> methods, in registration order (the paper's groups first, then the ablations)."""
    out: dict[str, list[str]] = {}
    for name, spec in registry.all_methods().items():
        out.setdefault(spec.group, []).append(name)
    ordered = [g for g in out if g not in registry.ABLATION_GROUPS] + [g for g in registry.ABLATION_GROUPS if g in out]
    return {g: tuple(out[g]) for g in ordered}


class _Labels(Mapping):
    """name -> label of every registered method, read from the registry at each lookup."""

    def __getitem__(self, name: str) -> str:
        methods = registry.all_methods()
        if name not in methods:
            raise KeyError(name)
        return methods[name].label

    def __iter__(self) -> Iterator[str]:
        return iter(registry.all_methods())

    def __len__(self) -> int:
        return len(registry.all_methods())


LABELS: Mapping[str, str] = _Labels()


def parse_methods(text: str | None) -> list[str]:
    """Comma list -> method names in table order; None/'all' -> `default_methods()`."""
    methods = selectable()
    if text is None or text.strip() == "all":
        return list(default_methods())
    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in methods]
    if unknown or not names:
        raise InputError(f"--methods: unknown method(s) {', '.join(unknown) or '(none given)'}; choose from {', '.join(methods)}")
    return [m for m in methods if m in names]

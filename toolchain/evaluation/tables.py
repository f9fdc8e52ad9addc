"""The paper-style results table in Markdown, from an evaluation's JSON result.

Rows grouped Fine-tuned / Merging / Distillation (then the ablations, which are not
ranked); for every calibration size two columns, balanced accuracy and macro-F1 as
mean ± std over the runs. Per column the best method is bold and the second
underlined; † marks the best when the corrected resampled t-test against the second
is significant (p < 0.05, Nadeau-Bengio form, see `stats`).
"""

from __future__ import annotations

from .methods import LABELS, table_groups
from .metrics import SCALAR_METRICS

COLUMN_NAMES = {"balanced_accuracy": "Bal. Acc.", "macro_f1": "Macro F1"}
CLASS_NAMES = ("low", "moderate", "high")


def _cell(stats: dict, rank: int | None, dagger: bool) -> str:
    text = f"{stats['mean']:.4f} ± {stats['std']:.4f}"
    if rank == 0:
        return f"**{text}**" + ("†" if dagger else "")
    if rank == 1:
        return f"<u>{text}</u>"
    return text


def markdown_table(result: dict) -> str:
    results, ttest, cfg = result["results"], result.get("ttest", {}), result.get("config", {})
    sizes = list(next(iter(results.values())).keys())
    header = ["Group", "Method"] + [f"{COLUMN_NAMES[m]} (D_Cal={c})" for c in sizes for m in SCALAR_METRICS]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for group, methods in table_groups().items():
        present = [m for m in methods if m in results]
        for i, m in enumerate(present):
            cells = [group if i == 0 else "", LABELS.get(m, m)]
            for c in sizes:
                for metric in SCALAR_METRICS:
                    test = ttest.get(c, {}).get(metric, {})
                    ranking = test.get("ranking", [])
                    rank = ranking.index(m) if m in ranking[:2] else None
                    cells.append(_cell(results[m][c][metric], rank, bool(test.get("significant"))))
            lines.append("| " + " | ".join(cells) + " |")
    notes = [
        "",
        f"{cfg.get('arch', '?').upper()}, protocol `{cfg.get('protocol', '?')}`, mean ± std (ddof=1) over "
        f"{cfg.get('runs', '?')} MCCV runs; best **bold**, second <u>underlined</u>; † best significantly better "
        "than second (corrected resampled t-test, p < 0.05).",
        *_noise_note(result),
        "",
        "Best vs second (t-test, df = runs − 1; p with the Nadeau-Bengio factor 1/n + n_test/n_train, and with "
        "the reference notes' factor 1/n + n_train/n_test):",
        "",
    ]
    for c in sizes:
        for metric in SCALAR_METRICS:
            test = ttest.get(c, {}).get(metric, {})
            if "tests" not in test:
                continue
            nb, ref = test["tests"]["nadeau-bengio"], test["tests"]["reference"]
            notes.append(
                f"- D_Cal={c}, {COLUMN_NAMES[metric]}: {LABELS.get(test['best'], test['best'])} vs "
                f"{LABELS.get(test['second'], test['second'])}: mean diff {nb['mean_diff']:+.4f}, "
                f"t = {nb['t']:.3f}, p = {nb['p']:.4f} (reference form: t = {ref['t']:.3f}, p = {ref['p']:.4f}); "
                f"n_train = {test['n_train']}, n_test = {test['n_test']:.0f}"
            )
    return "\n".join(lines + notes + [""] + per_class_table(result) + fit_table(result)) + "\n"


def per_class_table(result: dict) -> list[str]:
    """Per-class precision and recall (mean ± std over runs) at every calibration size."""
    results = result["results"]
    lines = ["Per-class precision / recall (mean ± std over runs):", ""]
    for c in next(iter(results.values())):
        header = ["Method"] + [f"{k} {cls} (D_Cal={c})" for cls in CLASS_NAMES for k in ("P", "R")]
        lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for m in results:
            e = results[m][c]
            cells = [f"{e[k]['mean'][i]:.2f} ± {e[k]['std'][i]:.2f}" for i in range(len(CLASS_NAMES))
                     for k in ("precision", "recall")]
            lines.append("| " + " | ".join([LABELS.get(m, m), *cells]) + " |")
        lines.append("")
    return lines


def fit_table(result: dict) -> list[str]:
    """Balanced accuracy on D_Cal itself beside the test score: a large gap means the method
    fitted the calibration rows more than the test rows reward (over-fitting D_Cal)."""
    results = result["results"]
    if not all("calibration_fit" in e for m in results.values() for e in m.values()):
        return []  # results written before the fit was recorded
    sizes = list(next(iter(results.values())))
    header = ["Method"] + [f"{k} (D_Cal={c})" for c in sizes for k in ("on D_Cal", "on test", "gap")]
    lines = ["Balanced accuracy on the calibration rows vs on the test rows (mean over runs):", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for m in results:
        cells = [LABELS.get(m, m)]
        for c in sizes:
            fit, test = results[m][c]["calibration_fit"]["balanced_accuracy"]["mean"], results[m][c]["balanced_accuracy"]["mean"]
            cells += [f"{fit:.3f}", f"{test:.3f}", f"{fit - test:+.3f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _noise_note(result: dict) -> list[str]:
    """What the methods were calibrated on, when D_Cal's labels were corrupted (the test labels never are)."""
    noise = result.get("config", {}).get("label_noise")
    if not noise:
        return []
    first = next(iter(result["results"].values()))
    parts = [f"|D_Cal| = {c}: {e['label_noise']['corrupted_mean']:.1f} labels changed per run "
             f"({100 * e['label_noise']['corrupted_fraction']:.1f} %)" for c, e in first.items() if "label_noise" in e]
    return ["", f"D_Cal's labels corrupted by `{noise}` (seeded per run, the same for every method; the test rows' "
            f"labels exact): {'; '.join(parts)}."]

"""REPRODUCTION.md's tables and figures from the JSON lines of `table1_runs` and `noisy_runs`.

Each `*_markdown` function returns a markdown table; `figure_*` write a small PNG (matplotlib,
imported there only). Rows missing from a run (a method skipped, a run still going) show as `-`.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import numpy as np

from .noisy_runs import DECISION_QUANTILE

PAPER_TABLE2 = {"egnc": 19, "risam": 15}
"""The paper's Table 2: successes out of 50 noisy-Manhattan datasets, online (iSAM2)."""
PAPER_TIME_RATIO = 0.6
"""The paper's Table 1: EGNC's time over riSAM's, about 0.6 (DESIGN.md section 5)."""
REGIMES = {"chi2": "paper rule, r^2 > 7.81", "r2>90": "gross, r^2 > 90"}


def _pr(row: dict | None) -> str:
    """`P / R` of a run, or its status."""
    if row is None:
        return "-"
    if row.get("status", "ok") != "ok":
        return row["status"]
    return f"{row['P']:.4f} / {row['R']:.4f}"


def table1_markdown(rows: list[dict]) -> str:
    """Table 1: online egnc and risam (P / R, iterations, time, ratio), batch columns beside."""
    by = {(r["dataset"], r["percent"], r["mode"], r["method"]): r for r in rows}
    cases = list(dict.fromkeys((r["dataset"], r["percent"]) for r in rows))
    lines = [
        "| log | % | online egnc P / R | online risam P / R | iterations egnc / risam | time s egnc / risam"
        " | time ratio | batch egnc P / R, s | GTSAM GNC-TLS P / R, s |",
        "|---|---:|---|---|---|---|---:|---|---|",
    ]
    for name, percent in cases:
        egnc, risam = by.get((name, percent, "online", "egnc")), by.get((name, percent, "online", "risam"))
        both = egnc is not None and risam is not None
        iterations = f"{egnc['iterations']} / {risam['iterations']}" if both else "-"
        seconds = f"{egnc['total_s']:.1f} / {risam['total_s']:.1f}" if both else "-"
        ratio = f"{egnc['total_s'] / risam['total_s']:.2f}x" if both else "-"
        batch = [by.get((name, percent, "batch", method)) for method in ("egnc", "gtsam-gnc-tls")]
        cells = [f"{_pr(b)}, {b['total_s']:.2f}" if b and b.get("status") == "ok" else _pr(b) for b in batch]
        lines.append(
            f"| {name} | {percent:g} | {_pr(egnc)} | {_pr(risam)} | {iterations} | {seconds} | {ratio}"
            f" | {cells[0]} | {cells[1]} |"
        )
    return "\n".join(lines) + "\n"


def table2_markdown(rows: list[dict]) -> str:
    """Table 2: successes per regime, mode and method, mean recall, the paper's counts beside."""
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for row in rows:
        groups[(row["regime"], row["mode"], row["method"])].append(row)
    lines = [
        "| outliers | mode | egnc | risam | gnc-tls | paper, online: EGNC / riSAM |",
        "|---|---|---|---|---|---|",
    ]
    for regime in [r for r in REGIMES if any(key[0] == r for key in groups)]:
        for mode in ("online", "batch"):
            cells = []
            for method in ("egnc", "risam", "gnc-tls"):
                runs = groups.get((regime, mode, method), [])
                if not runs:
                    cells.append("-")
                    continue
                ok = sum(run["ok"] for run in runs)
                cells.append(f"**{ok}/{len(runs)}**, R {np.mean([run['R'] for run in runs]):.4f}")
            paper = f"{PAPER_TABLE2['egnc']}/50 / {PAPER_TABLE2['risam']}/50" if mode == "online" else ""
            lines.append(f"| {REGIMES[regime]} | {mode} | {' | '.join(cells)} | {paper} |")
    return "\n".join(lines) + "\n"


def failures_markdown(rows: list[dict], regime: str) -> str:
    """Every run of `regime` that failed: the outliers kept and true loops rejected, with their `r^2`.

    `r^2` at the outlier-free optimum (ref) tells how far above the paper's threshold an outlier
    sits; at the final map (final), what the method saw when it kept it.
    """
    lines = [
        "| seed | mode | method | outliers kept | their r^2 at ref (min-max) | at final map (max)"
        " | true loops rejected | truncated cost: run / outlier-free optimum |",
        "|---:|---|---|---:|---|---|---:|---|",
    ]
    for row in sorted((r for r in rows if r["regime"] == regime and not r["ok"]), key=_order):
        missed, wrong = row["missed"], row["rejected_true"]
        ref = f"{min(missed['r2_ref']):.1f}-{max(missed['r2_ref']):.1f}" if missed["index"] else "-"
        final = f"{max(missed['r2_final']):.1f}" if missed["index"] else "-"
        kept = ", ".join(str(i) for i in missed["index"]) if len(missed["index"]) <= 3 else str(len(missed["index"]))
        lines.append(
            f"| {row['seed']} | {row['mode']} | {row['method']} | {kept} | {ref} | {final}"
            f" | {len(wrong['index'])} | {row['tc']:.1f} / {row['tc_ref']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def _order(row: dict) -> tuple:
    return (row["seed"], row["mode"] != "online", ("egnc", "risam", "gnc-tls").index(row["method"]))


def criterion_summary(rows: list[dict], regime: str) -> dict:
    """How egnc's batch decision compares with gnc-tls's and the truth's under the truncated cost.

    Returns counts over the seeds of `regime` with both batch runs: `tls_lower` (gnc-tls's map has
    the lower truncated cost), `truth_higher` (the outlier-free optimum's cost is above the lower of
    the two by more than rounding: the criterion prefers a wrong decision to the labels), and the
    seeds' median costs.
    """
    batch = {(r["seed"], r["method"]): r for r in rows if r["regime"] == regime and r["mode"] == "batch"}
    seeds = sorted({seed for seed, method in batch if method == "egnc" and (seed, "gnc-tls") in batch})
    egnc = np.array([batch[(s, "egnc")]["tc"] for s in seeds])
    tls = np.array([batch[(s, "gnc-tls")]["tc"] for s in seeds])
    truth = np.array([batch[(s, "egnc")]["tc_ref"] for s in seeds])
    lower = tls < egnc * (1 - 1e-9)
    recall_gain = [batch[(s, "gnc-tls")]["R"] - batch[(s, "egnc")]["R"] for s in np.array(seeds)[lower]]
    return {
        "seeds": len(seeds),
        "tls_lower": int(lower.sum()),
        "tls_lower_recall_gain": float(np.mean(recall_gain)) if recall_gain else 0.0,
        "truth_higher": int(np.sum(truth > np.minimum(egnc, tls) * (1 + 1e-9))),
        "median_egnc": float(np.median(egnc)) if seeds else float("nan"),
        "median_tls": float(np.median(tls)) if seeds else float("nan"),
        "median_truth": float(np.median(truth)) if seeds else float("nan"),
        "quantile": DECISION_QUANTILE,
    }


def table3_markdown(rows: list[dict]) -> str:
    """Table 3: the shipped case and the datasets where risam failed, egnc and risam side by side (online first)."""
    by = {(r["regime"], r["seed"], r["mode"], r["method"]): r for r in rows}
    lines = [
        "| dataset | mode | method | P | R | ATE m (opt) | RPE % (opt) | ATE m (truth) | RPE % (truth) | time s |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for regime, seed, mode, method in sorted(by, key=lambda k: (k[0], k[1], k[2] != "online", k[3])):
        row = by[(regime, seed, mode, method)]
        name = "manhattan_noisy.irl" if regime == "irl" else f"{regime} seed {seed}"
        lines.append(
            f"| {name} | {mode} | {method} | {row['P']:.4f} | {row['R']:.4f} | {row['ate']:.3f}"
            f" | {row['rpe_percent']:.2f} | {row['ate_truth']:.3f} | {row['rpe_truth_percent']:.2f}"
            f" | {row['time_s']:.1f} |"
        )
    return "\n".join(lines) + "\n"


def figure_table1(rows: list[dict], path: Path) -> Path:
    """egnc's online time over risam's per log (bars, log scale), the paper's 0.6 as a line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {(r["dataset"], r["percent"], r["method"]): r for r in rows if r["mode"] == "online"}
    cases = [key for key in dict.fromkeys((d, p) for d, p, _ in by) if (*key, "risam") in by and (*key, "egnc") in by]
    ratios = [by[(*key, "egnc")]["total_s"] / by[(*key, "risam")]["total_s"] for key in cases]
    iterations = [by[(*key, "egnc")]["iterations"] / by[(*key, "risam")]["iterations"] for key in cases]
    figure, axes = plt.subplots(figsize=(7.5, 3.2))
    x = np.arange(len(cases))
    axes.bar(x - 0.2, ratios, 0.4, label="time")
    axes.bar(x + 0.2, iterations, 0.4, label="iterations")
    axes.axhline(PAPER_TIME_RATIO, color="k", ls="--", lw=1, label="paper, time (about 0.6)")
    axes.axhline(1.0, color="grey", lw=0.8)
    axes.set_yscale("log")
    axes.set_ylim(0.3, 1.5)
    axes.set_xticks(x, [f"{d[:9]}\n{p:g}%" for d, p in cases], fontsize=7)
    axes.set_ylabel("egnc / risam, online")
    axes.legend(fontsize=7, loc="upper right")
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path


def figure_table2(rows: list[dict], path: Path) -> Path:
    """Successes out of the seeds per regime and mode, bars per method, the paper's beside."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    counts: dict[tuple, int] = defaultdict(int)
    totals: dict[tuple, int] = defaultdict(int)
    for row in rows:
        counts[(row["regime"], row["mode"], row["method"])] += int(row["ok"])
        totals[(row["regime"], row["mode"], row["method"])] += 1
    groups = [(regime, mode) for regime in REGIMES for mode in ("online", "batch")]
    groups = [g for g in groups if any(key[:2] == g for key in counts)]
    figure, axes = plt.subplots(figsize=(7.5, 3.2))
    x = np.arange(len(groups) + 1)
    for k, method in enumerate(("egnc", "risam", "gnc-tls")):
        values = [counts.get((*g, method), 0) for g in groups] + [PAPER_TABLE2.get(method, 0)]
        runs = [totals.get((*g, method), 0) for g in groups] + [50 if method in PAPER_TABLE2 else 0]
        bars = axes.bar(x + (k - 1) * 0.27, values, 0.27, label=method)
        for bar, value, n in zip(bars, values, runs, strict=True):
            if n:  # successes out of the datasets run: the online rows may be partial
                axes.annotate(f"{value}/{n}", (bar.get_x() + bar.get_width() / 2, value), ha="center",
                              va="bottom", fontsize=6)  # fmt: skip
    labels = [f"{REGIMES[r].split(',')[0]}\n{m}" for r, m in groups] + ["paper\nonline"]
    axes.set_xticks(x, labels, fontsize=8)
    axes.set_ylabel("successes (P = R = 1)")
    axes.set_ylim(0, 52)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)
    return path

"""Assemble BENCHMARKS.md from the per-benchmark result files in benchmarks/results/ (run after benchmarking)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ORDER = ["tfp", "random_access", "guided", "temporal", "lowlight", "colour", "roi_knob", "ffdnet", "prior", "prior_xeon", "cli", "cli_xeon", "gpu", "tiles", "sd", "sim", "gui", "gui_stall", "ui_stalls", "ui_stalls_xeon", "live", "geometry", "geometry_wide", "cluster", "conformance"]
SUMMARY = (ROOT / "benchmarks" / "summary.md").read_text(encoding="utf-8")


def demote(text: str) -> str:
    out = []
    for line in text.splitlines():
        if line.startswith("#"):
            line = "#" + line
        out.append(line.replace("](guided_pareto.png)", "](benchmarks/results/guided_pareto.png)"))
    return "\n".join(out)


parts = [SUMMARY.rstrip()]
for name in ORDER:
    f = ROOT / "benchmarks" / "results" / f"{name}.md"
    if f.exists():
        parts.append(demote(f.read_text(encoding="utf-8")).rstrip())
(ROOT / "BENCHMARKS.md").write_text("\n\n".join(parts) + "\n", encoding="utf-8")
print("wrote BENCHMARKS.md")

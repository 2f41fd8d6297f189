"""What the benchmark scripts share: the CPU's name for the report header, and writing the report."""

from __future__ import annotations

from pathlib import Path


def cpu_model(default: str = "unknown CPU") -> str:
    """The CPU's model name from ``/proc/cpuinfo`` (``default`` where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return default


def write_report(out: Path, lines: list[str]) -> int:
    """Write the report's lines to ``out`` (its folder made), say so, and return the exit status 0."""
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"wrote {out}")
    return 0

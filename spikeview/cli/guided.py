"""Guided settings from the command line (kept for the batch path; the flags come from the recipe)."""

from __future__ import annotations

import argparse
from typing import Any


def _guided_config(args: argparse.Namespace, preset: dict[str, Any] | None = None):
    """The :class:`~spikeview.guided.GuidedConfig` of the recipe the flags and ``--preset`` give."""
    from spikeview.cli.reconstruct import recipe_from_args

    return recipe_from_args(args).guided

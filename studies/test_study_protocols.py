"""Every study's protocol file loads, and only a study that runs X-mix declares a study control (issue 60): the
converged study (its value: studies/converged/tests/test_converged_controls.py); the others run no X-mix."""

from __future__ import annotations

from pathlib import Path

import pytest

from freespace.experiments import Protocol

STUDIES = Path(__file__).resolve().parent
#: the studies whose protocol declares a study control
WITH_CONTROLS = {"converged"}


@pytest.mark.parametrize("study", sorted(p.parent.name for p in STUDIES.glob("*/protocol.yaml")))
def test_a_study_declares_the_controls_of_the_variants_it_runs(study: str) -> None:
    protocol = Protocol.load(STUDIES / study / "protocol.yaml")
    assert bool(protocol.controls) == (study in WITH_CONTROLS), protocol.controls

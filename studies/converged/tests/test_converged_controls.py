"""The converged study declares the study control its X-mix arm reads (issue 60): the share of the training drives
that keep people's labels comes from this study's protocol file, not from the library."""

from __future__ import annotations

from pathlib import Path

from freespace.experiments import Protocol

STUDY = Path(__file__).resolve().parents[1]


def test_the_converged_study_declares_its_mix_share() -> None:
    protocol = Protocol.load(STUDY / "protocol.yaml")
    assert protocol.controls == {"mix_human_share": 0.2}
    assert protocol.control_values("X-mix") == {"human_share": 0.2}
    assert protocol.control_values("X") == {}

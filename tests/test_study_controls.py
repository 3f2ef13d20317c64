"""Study controls declared by the study (issue 60): a value a built-in variant needs that the paper does not fix
(X-mix's share of the drives that keep people's labels) comes from the study's protocol file, not the library.
The studies' own declarations are tested with the studies (studies/converged/tests/test_converged_controls.py,
studies/test_study_protocols.py), so that these tests pass in a checkout without ``studies/``."""

from __future__ import annotations

from pathlib import Path

import pytest

from freespace.errors import InvalidOptionError
from freespace.experiments import variants
from freespace.experiments.protocol import Protocol
from freespace.experiments.variants import CONTROLS, VARIANTS


def _load(tmp_path: Path, text: str) -> Protocol:
    path = tmp_path / "protocol.yaml"
    path.write_text(text)
    return Protocol.load(path)


def test_the_library_holds_the_mechanism_and_no_study_value() -> None:
    assert not hasattr(variants, "MIX_HUMAN_SHARE")
    assert VARIANTS["X-mix"].controls == ("mix_human_share",) and CONTROLS["mix_human_share"].field == "human_share"
    assert Protocol().controls == {}  # the method's defaults declare none


def test_x_mix_without_the_control_is_refused_naming_it(tmp_path: Path) -> None:
    with pytest.raises(InvalidOptionError, match=r"X-mix reads the study control mix_human_share .*controls: "
                                                 r"\{mix_human_share: VALUE\}"):
        Protocol().control_values("X-mix")
    assert _load(tmp_path, "variants: [X]\ngains: [X-mix - X]\ncontrols: {mix_human_share: 0.5}\n") \
        .control_values("X-mix") == {"human_share": 0.5}


@pytest.mark.parametrize("text,match", [
    ("variants: [X]\ngains: [X-mix - X]\ncontrols: {mix_share: 0.2}\n", "unknown control 'mix_share'"),
    ("variants: [X]\ngains: [X-mix - X]\ncontrols: [0.2]\n", "controls must map study controls to values"),
    ("variants: [X, HA-X]\ngains: [HA-X - X]\ncontrols: {mix_human_share: 0.2}\n",
     "mix_human_share is read by X-mix, which this protocol neither runs nor reports"),
    ("variants: [X]\ngains: [X-mix - X]\ncontrols: {mix_human_share: 1}\n", "strictly between 0 and 1"),
    ("variants: [X]\ngains: [X-mix - X]\ncontrols: {mix_human_share: true}\n", "strictly between 0 and 1"),
    ("variants: [X]\ngains: [X-mix - X]\ncontrols: {mix_human_share: '0.2'}\n", "got '0.2'"),
])
def test_a_bad_control_is_refused_in_one_line(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(InvalidOptionError, match=match) as caught:
        _load(tmp_path, text)
    assert "\n" not in str(caught.value)


def test_a_cell_of_x_mix_takes_the_share_from_the_protocol(tmp_path: Path) -> None:
    """The cell's configuration (its config.yaml) carries the protocol's share; without one it is refused before
    any cell trains."""
    from freespace.cli import main
    from freespace.data.synthetic import SynthConfig, write_dataset
    from freespace.experiments.cells import cell_config

    data, labels = tmp_path / "syn", tmp_path / "labels"
    write_dataset(data, 4, seed=0, progress=False, config=SynthConfig(width=96, height=64, frames_per_scenario=2))
    assert main(["-q", "autolabel", "--dataset", "kitti", "--root", str(data), "--out", str(labels)]) == 0
    options = {"epochs": 1, "patience": 1, "image_size": (64, 64)}
    protocol = _load(tmp_path, "variants: [X]\ngains: [X-mix - X]\ncontrols: {mix_human_share: 0.5}\n")
    config = cell_config("kitti", data, tmp_path / "o", "segnet", "X-mix", 0, options, labels, protocol)
    assert config.human_share == 0.5 and config.labels == str(labels)
    assert cell_config("kitti", data, tmp_path / "o", "segnet", "X-auto", 0, options, labels,
                       protocol).human_share == 0.0
    with pytest.raises(InvalidOptionError, match="mix_human_share"):
        cell_config("kitti", data, tmp_path / "o", "segnet", "X-mix", 0, options, labels)

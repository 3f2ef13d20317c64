"""One name per dataset layout (issue 60): help and messages show the layouts' names only; the names of earlier
versions stay accepted, quietly, and are read as the layout's name."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from freespace.data.registry import canonical_dataset, get_dataset_class, list_datasets
from freespace.errors import InvalidOptionError

from helpers import refused

#: the layouts' names, and the earlier names each still answers to
NAMES = {"kitti": ("kitti_road", "synth"), "kitti-raw": ("kitti_raw",), "synthia": (), "carla": ("syn-stereo",),
         "generic": ()}


def test_one_name_per_layout_and_the_earlier_names_as_aliases() -> None:
    assert list_datasets(aliases=False) == sorted(NAMES)
    assert len({get_dataset_class(n) for n in NAMES}) == len(NAMES)  # five layouts, five names
    every = {n for name, aliases in NAMES.items() for n in (name, *aliases)}
    assert set(list_datasets()) == every  # the default: every name accepted
    for name, aliases in NAMES.items():
        assert get_dataset_class(name).name == name
        for alias in (name, *aliases):
            assert canonical_dataset(alias) == name
            assert get_dataset_class(alias) is get_dataset_class(name)


def test_an_unknown_name_lists_the_layouts_names_only() -> None:
    with pytest.raises(InvalidOptionError) as caught:
        canonical_dataset("kitty")
    message = str(caught.value)
    assert "kitty" in message and "carla, generic, kitti, kitti-raw, synthia" in message
    assert not any(re.search(rf"\b{re.escape(a)}\b", message) for a in ("synth", "kitti_road", "kitti_raw",
                                                                        "syn-stereo"))


@pytest.mark.parametrize("command", [["datasets", "info"], ["datasets", "split"], ["generate"], ["autolabel"],
                                     ["evaluate"]])
def test_help_shows_the_layouts_names_only(command: list[str], capsys: pytest.CaptureFixture) -> None:
    from freespace.cli import main

    with pytest.raises(SystemExit):
        main([*command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "{carla,generic,kitti,kitti-raw,synthia}" in text
    for alias in ("kitti_road", "kitti_raw", "syn-stereo"):
        assert alias not in text
    assert "--dataset synth" not in text and "{synth" not in text and ",synth}" not in text


def test_an_earlier_name_on_the_command_line_is_read_as_the_layouts(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture) -> None:
    from freespace.cli import main
    from freespace.data.synthetic.dataset import write_dataset
    from freespace.data.synthetic.scene import SynthConfig

    write_dataset(tmp_path / "syn", 2, config=SynthConfig(width=64, height=48, frames_per_scenario=2), seed=0,
                  progress=False)
    for name in ("synth", "kitti_road", "kitti"):
        assert main(["-q", "datasets", "info", "--dataset", name, "--root", str(tmp_path / "syn"),
                     "--no-progress"]) in (0, 1)
        assert capsys.readouterr().out.startswith("kitti at ")
    err = refused(capsys, ["datasets", "info", "--dataset", "kitty", "--root", str(tmp_path)])
    assert "'carla', 'generic', 'kitti', 'kitti-raw', 'synthia'" in err and "'synth'" not in err  # argparse's words


@pytest.mark.parametrize("alias", ["synth", "kitti_road", "kitti_raw", "syn-stereo"])
def test_the_options_of_a_layout_follow_its_aliases(alias: str, tmp_path: Path) -> None:
    """open_dataset (a dataset from a command's options) checks ``disparity_dir`` and ``lidar_densify`` against the
    layout an earlier name means, as the command line (which canonicalises the name) does; a layout that reads the
    option goes on to the missing root."""
    from freespace.data.options import open_dataset
    from freespace.errors import FreespaceError

    def refusal(**options: object) -> str:
        with pytest.raises(FreespaceError) as caught:
            open_dataset(alias, tmp_path / "none", **options)  # type: ignore[arg-type]
        return str(caught.value)

    layout = canonical_dataset(alias)
    by_dir = refusal(disparity_dir=tmp_path)
    assert ("disparity_dir is for KITTI road trees" in by_dir) == (layout != "kitti"), by_dir
    by_lidar = refusal(disparity_source="lidar", lidar_densify=2.0)
    assert ("lidar_densify is for KITTI road and KITTI raw" in by_lidar) == (layout not in ("kitti", "kitti-raw"))

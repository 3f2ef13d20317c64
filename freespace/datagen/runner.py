"""The resumable, sharded per-frame dataset runner of the per-frame commands (``generate``, ``autolabel``).

A per-frame command is a :class:`FrameCommand`: its name, the work of one frame, the columns of its report
CSV and the totals of its summary. :func:`run_dataset` runs it over every frame of a
:class:`~freespace.data.base.StereoRoadDataset` into one output folder:

* ``OUT/<frame>.png`` and ``OUT/reports/<frame>.json`` per frame (plus ``OUT/<extra>/<frame>.png`` for each
  of the command's extra folders), written by the command's work;
* ``OUT/report.csv`` (a row per frame) and ``OUT/summary.json`` (counts, failures, means); with the shard
  ``(K, N)`` ``report.shard-K-of-N.csv`` and ``summary.shard-K-of-N.json``, so that shards never overwrite
  each other's;
* ``OUT/settings.json``: what the outputs depend on (never the shard, so that the shards of one run share
  the folder). A folder made with other settings is refused, unless ``overwrite``.

Resumable: a frame whose image and report exist, made with these settings, is skipped. A failing frame is
recorded with its reason and does not stop the run. The folder follows :mod:`freespace.io.outdir` (manifest
and lock; shards share it). Frames run in this process or in worker processes
(:mod:`freespace.runtime.parallel`). Only NumPy and OpenCV are imported (never torch).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from freespace.data.base import FrameRef, StereoRoadDataset
from freespace.errors import InvalidOptionError, param
from freespace.io.files import PathLike, check_outputs, check_writable, write_csv, write_json
from freespace.io.outdir import check_settings, claim_folder
from freespace.runtime.shard import select_shard

log = logging.getLogger(__name__)

__all__ = ["FrameCommand", "FrameWork", "SETTINGS_NAME", "check_run", "frames_folder", "recorded_settings",
           "run_dataset", "run_report", "totals_names"]

#: the work of one frame: ``work(dataset, index, out, report, options, settings)`` writes the frame's
#: ``out`` image (and its extra files) and ``report`` JSON, and returns its record (``frame``, ``status``
#: ``done`` or ``failed`` with a ``reason``, and the report's fields); it never raises. A module-level
#: function, so that worker processes can run it.
FrameWork = Callable[[StereoRoadDataset, int, Path, Path, Any, dict[str, Any]], dict[str, Any]]

SETTINGS_NAME = "settings.json"


@dataclass(frozen=True)
class FrameCommand:
    """A per-frame command, for :func:`run_dataset`.

    Attributes:
        name: the command (``generate``): the owner of the output folder, the progress bar's label.
        verb: what it does to a frame, for the log (``label``: "12 frames: 3 to label, 9 already done").
        work: the work of one frame (:data:`FrameWork`).
        fields: the columns of the report CSV, record keys (``seconds``: the record's ``seconds.total``).
        done: the summary's count of frames done by this run (``generated``).
        means: the summary's statistics of the records that did not fail (a dict, in the summary after the
            counts).
        extra: folders that hold one more ``<frame>.png`` per frame (autolabel's ``confidence``).
    """

    name: str
    verb: str
    work: FrameWork
    fields: tuple[str, ...]
    done: str
    means: Callable[[list[dict[str, Any]]], dict[str, Any]]
    extra: tuple[str, ...] = ()


def recorded_settings(recorded: dict[str, Any]) -> dict[str, Any]:
    """Settings recorded by an earlier version under the names of today's (``disparity``: ``disparity_source``)."""
    return {("disparity_source" if k == "disparity" else k): v for k, v in recorded.items()}


def totals_names(shard: tuple[int, int] | None) -> tuple[str, str]:
    """``(summary, report)`` file names: ``summary.json``/``report.csv``, or for the shard ``(K, N)``
    ``summary.shard-K-of-N.json``/``report.shard-K-of-N.csv`` (shards never overwrite each other's)."""
    if shard is None:
        return "summary.json", "report.csv"
    return f"summary.shard-{shard[0]}-of-{shard[1]}.json", f"report.shard-{shard[0]}-of-{shard[1]}.csv"


def check_run(dataset: StereoRoadDataset, out_dir: PathLike, workers: int) -> Path:
    """Refuse, before any work, ``workers`` below 1 and an ``out_dir`` that cannot be the output folder (not
    writable as a folder, or inside the dataset's root, or holding it); return ``out_dir`` (``~`` expanded)."""
    if workers < 1:
        raise InvalidOptionError(f"{param('workers')} must be ≥ 1, got {workers}")
    out_dir = check_writable(out_dir, folder=True)  # no device, pipe, /proc, a file, … (freespace.io.files)
    check_outputs({"out": out_dir}, {"root": dataset.root})
    return out_dir


def run_dataset(dataset: StereoRoadDataset, out_dir: Path, command: FrameCommand, *, options: Any,
                settings: dict[str, Any], workers: int, progress: bool, overwrite: bool,
                shard: tuple[int, int] | None, summary: dict[str, Any]) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """Run ``command`` over the frames of ``dataset`` (of its shard ``(K, N)``, 1-based, when given) that
    ``out_dir`` lacks, in ``workers`` processes, and write the report CSV and the summary.

    Args:
        dataset: the whole dataset (the shard is taken here).
        out_dir: the output folder, checked (:func:`check_run`).
        options: the command's options, passed to each frame's work.
        settings: what the outputs depend on (``settings.json``, and every frame's report), the shard never.
        summary: the summary's last entries (e.g. the options).

    Returns:
        ``(summary, records)``: the summary as written (``dataset``, ``root``, ``shard``, ``frames``, the
        done count, ``skipped``, ``failed`` (frame → reason), the means, ``wall_seconds``, ``workers``, then
        ``summary``), and the frames' records in frame order.
    """
    if shard is not None:
        dataset = dataset.subset(select_shard((f.name for f in dataset.frames), *shard))
    with frames_folder(out_dir, command.name, settings, overwrite, [f.name for f in dataset.frames], shard,
                       extra=command.extra):
        t0 = time.perf_counter()
        records = _run_frames(dataset, out_dir, command, options, settings, shard, workers, progress)
        ok = [r for r in records if r["status"] != "failed"]
        totals = {"dataset": dataset.name, "root": str(dataset.root),
                  **({"shard": f"{shard[0]}/{shard[1]}"} if shard is not None else {}),
                  "frames": len(records), command.done: sum(r["status"] == "done" for r in records),
                  "skipped": sum(r["status"] == "skipped" for r in records),
                  "failed": {r["frame"]: r["reason"] for r in records if r["status"] == "failed"},
                  **command.means(ok), "wall_seconds": round(time.perf_counter() - t0, 3), "workers": workers,
                  **summary}
        write_json(out_dir / totals_names(shard)[0], totals)
    return totals, records


@contextmanager
def frames_folder(out_dir: Path, command: str, settings: dict[str, Any], overwrite: bool, names: list[str],
                  shard: tuple[int, int] | None, extra: tuple[str, ...] = ()) -> Iterator[None]:
    """Hold ``out_dir`` for a per-frame dataset output of ``command`` (``generate``, ``autolabel``): the
    folder rule of :mod:`freespace.io.outdir` (shards share it), the recorded ``settings`` (a folder made with
    other ones is refused unless ``overwrite``, which first removes what this run or shard would write),
    and every file of the frames ``names`` listed in the manifest before it is written: ``<frame>.png``,
    ``reports/<frame>.json``, ``<extra>/<frame>.png``, the totals and ``settings.json``."""
    summary_name, report_name = totals_names(shard)
    mine = {SETTINGS_NAME, "summary.json", "report.csv", summary_name, report_name,
            *(f"{n}.png" for n in names), *(f"reports/{n}.json" for n in names),
            *(f"{e}/{n}.png" for e in extra for n in names)}
    with claim_folder(out_dir, command, shared=shard is not None) as folder:
        check_settings(out_dir / SETTINGS_NAME, settings, overwrite, f"frames made by freespace {command}",
                       recorded_as=recorded_settings)
        if overwrite:  # only what this run (or shard) would write, and the whole run's totals, now stale
            folder.forget(mine & folder.entries())
        folder.record(mine)
        write_json(out_dir / SETTINGS_NAME, settings)
        yield


def _run_frames(dataset: StereoRoadDataset, out_dir: Path, command: FrameCommand, options: Any,
                settings: dict[str, Any], shard: tuple[int, int] | None, workers: int,
                progress: bool) -> list[dict[str, Any]]:
    """Process the frames of ``dataset`` that ``out_dir`` lacks (:func:`_plan`: resumable, redone when made
    with other settings), log each failure and write the run's (or shard's) report CSV. Returns the frames'
    records in frame order."""
    frames = dataset.frames
    records, jobs = _plan(frames, out_dir, options, settings)
    log.info("%d frames: %d to %s, %d already done", len(frames), len(jobs), command.verb, len(records))
    records.update(_run_jobs(dataset, jobs, workers, progress, command.work, command.name))
    ordered = [records[f.name] for f in frames]
    for record in ordered:
        if record["status"] == "failed":
            log.warning("frame %s failed: %s", record["frame"], record["reason"])
    _write_report_csv(out_dir / totals_names(shard)[1], ordered, command.fields)
    return ordered


def _plan(frames: list[FrameRef], out_dir: Path, options: Any,
          settings: dict[str, Any]) -> tuple[dict[str, dict[str, Any]], list[tuple]]:
    """The records of frames already done with these settings, and the jobs of the others."""
    records: dict[str, dict[str, Any]] = {}
    jobs = []
    for i, frame in enumerate(frames):
        image_path = out_dir / f"{frame.name}.png"
        report_path = out_dir / "reports" / f"{frame.name}.json"
        if image_path.is_file() and report_path.is_file():
            try:
                report = json.loads(report_path.read_text())
                if recorded_settings(report.get("settings", settings)) == settings:  # (older runs' have none)
                    records[frame.name] = {**report, "status": "skipped"}
                    continue
                log.info("%s was made with other settings: making it again", frame.name)
            except (OSError, ValueError, AttributeError):
                pass  # unreadable report: do the frame again
        jobs.append((i, image_path, report_path, options, settings))
    return records, jobs


_DATASET: StereoRoadDataset | None = None  # the dataset of this worker process (set by _init_worker)


def _init_worker(dataset: StereoRoadDataset, parent: int) -> None:
    import cv2

    from freespace.runtime.parallel import init_worker

    init_worker(parent)
    global _DATASET
    _DATASET = dataset
    cv2.setNumThreads(1)


def _in_worker(work: FrameWork, *job: Any) -> dict[str, Any]:
    """``work(dataset, *job)`` with this worker process's dataset."""
    return work(_DATASET, *job)  # type: ignore[arg-type]


def _run_jobs(dataset: StereoRoadDataset, jobs: list[tuple], workers: int, progress: bool, work: FrameWork,
              desc: str) -> dict[str, dict[str, Any]]:
    """Run ``work(dataset, *job)`` over ``jobs`` in this process or in ``workers`` processes; ``desc`` names the
    progress bar."""
    from freespace.runtime.log import progress_bar

    records: dict[str, dict[str, Any]] = {}
    bar = progress_bar(None, total=len(jobs), desc=desc, unit="frame", enabled=progress and bool(jobs))
    if workers == 1 or len(jobs) <= 1:
        for job in jobs:
            record = work(dataset, *job)
            records[record["frame"]] = record
            bar.update()
    else:
        from freespace.runtime.parallel import worker_pool

        with worker_pool(workers, _init_worker, (dataset, os.getpid())) as pool:  # ends at once on Ctrl-C
            for future in as_completed([pool.submit(_in_worker, work, *job) for job in jobs]):
                record = future.result()
                records[record["frame"]] = record
                bar.update()
    bar.close()
    return records


def _write_report_csv(path: Path, records: list[dict[str, Any]], fields: tuple[str, ...]) -> None:
    rows = []
    for record in records:
        row = dict(record)
        seconds = record.get("seconds") or {}
        row["seconds"] = round(seconds.get("total", math.nan), 4) if seconds else ""
        rows.append(row)
    write_csv(path, list(fields), rows, extra="ignore")


def run_report(summary: dict[str, Any], done: str, out: PathLike, shard: str | None = None,
               spell: Callable[[str], str] = str) -> str:
    """What a dataset run prints of its ``summary`` (:func:`run_dataset`'s return value) into ``out``: one line of
    counts (``summary[done]`` frames made, e.g. ``done="generated"``; ``shard``: the run's ``"K/N"`` as given),
    then one line per failed frame, its reason's parameters written as ``spell(name)``."""
    failed, errors = summary["failed"], summary.get("errors", {})
    lines = [f"{summary[done]} {done}, {summary['skipped']} already done, {len(failed)} failed of "
             f"{summary['frames']} frames" + (f" (shard {shard})" if shard else "") + f" → {out}"]
    lines += [f"  failed {name}: {errors[name].render(spell) if name in errors else reason}"
              for name, reason in failed.items()]
    return "\n".join(lines)

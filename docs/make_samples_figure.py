"""Draw docs/samples.jpg for the README: built-in renderer samples with their generated views.

    .venv/bin/python docs/make_samples_figure.py
"""

from __future__ import annotations

from pathlib import Path

from freespace.data.synthetic import render_sample
from freespace.evaluation.viz import caption, colorize_disparity, grid, overlay_road
from freespace.geometry import fit_road_model, generate_view
from freespace.io.codecs import write_image


def main() -> None:
    rows = []
    for index in (0, 13, 36):
        s = render_sample(index, seed=0)
        model = fit_road_model(s.disparity, s.label.road)
        rows.append([caption(s.left, f"left {s.name} ({s.meta['weather']})"), caption(s.right, "right"),
                     caption(colorize_disparity(s.disparity), "disparity"),
                     caption(overlay_road(s.left, s.label.road), "road label"),
                     caption(generate_view(s.left, s.right, model), f"generated, roll {model.roll_deg:+.2f} deg")])
    out = Path(__file__).resolve().parent / "samples.jpg"
    write_image(out, grid(rows, width=320))
    print(out)


if __name__ == "__main__":
    main()

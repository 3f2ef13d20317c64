"""Training data from stereo files; never imports torch (but :mod:`freespace.datagen.road_look`'s encoder, when it
is called).

* :mod:`freespace.datagen.generate`: the DS-Generator over files (``freespace generate``);
* :mod:`freespace.datagen.virtual`: a reference image seen from a virtual camera pose;
* :mod:`freespace.datagen.labeller`: road labels from disparity alone; :mod:`freespace.datagen.autolabel`: the
  same over files and datasets (``freespace autolabel``);
* :mod:`freespace.datagen.runner`: the resumable, sharded per-frame dataset runner both commands use, and
  :mod:`freespace.datagen.inputs`: the dataset settings and checks they share;
* :mod:`freespace.datagen.propagate` and :mod:`freespace.datagen.road_look`: `freespace autolabel`'s passes over a
  label tree (the road later frames saw carried back; the road of another look vetoed).
"""

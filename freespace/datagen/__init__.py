"""Training data from stereo files: :mod:`freespace.datagen.generate` (the DS-Generator over files:
``freespace generate``) and :mod:`freespace.datagen.autolabel` (road labels from disparity alone:
``freespace autolabel``). Never imports torch."""

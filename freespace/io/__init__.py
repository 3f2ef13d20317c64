"""Files in and out; the lowest layer above the foundation (errors, log, labels).

* :mod:`freespace.io.files`: atomic writes (one file, or several all or nothing), JSON, CSV, checks of
  output paths before the work, the one-line errors for missing inputs;
* :mod:`freespace.io.outdir`: the one rule for output folders (manifest, lock, stages);
* :mod:`freespace.io.codecs`: images, disparity and depth maps, road label files;
* :mod:`freespace.io.kitti`: KITTI calibration files and Velodyne scans;
* :mod:`freespace.io.video`: frames of a video, folder or glob, and the atomic MP4 writer.

Only NumPy and OpenCV are imported here; never torch.
"""

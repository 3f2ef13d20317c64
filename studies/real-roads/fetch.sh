#!/usr/bin/env bash
# Lay out the study's two KITTI raw drives in KITTI raw's own layout, from git mirrors of two public
# repositories that carry them (the data never enters this repository):
#
#   SOFT=GITDIR UDACITY=GITDIR RAW=DIR bash studies/real-roads/fetch.sh
#
# SOFT: a git directory of github.com/Mayankm96/Stereo-Odometry-SOFT (commit 0106406 holds drive
# 2011_09_26_drive_0001_sync: cameras 00-03, 108 frames, and the day's calibration files).
# UDACITY: a git directory of github.com/udacity/SFND_3D_Object_Tracking (images/KITTI/2011_09_26: 78 left
# frames with Velodyne scans of another drive of that day, laid out as 2011_09_26_drive_0000_sync, its real
# number unknown). RAW: the KITTI raw root to write (RAW/2011_09_26/...). Skips a drive that is already there.
set -euo pipefail
: "${SOFT:?set SOFT to the Stereo-Odometry-SOFT git directory}" "${UDACITY:?set UDACITY to the SFND_3D_Object_Tracking git directory}" "${RAW:?set RAW to the KITTI raw root to write}"
DAY=$RAW/2011_09_26
D1=$DAY/2011_09_26_drive_0001_sync D0=$DAY/2011_09_26_drive_0000_sync
mkdir -p "$DAY"
tmp=$(mktemp -d) && trap 'rm -rf "$tmp"' EXIT
if [ ! -d "$D1/image_03/data" ]; then
    git --git-dir="$SOFT" archive 0106406 code/data/DataSet1 | tar -x -C "$tmp"
    src=$tmp/code/data/DataSet1
    cp "$src"/calib_*.txt "$DAY/"
    mkdir -p "$D1.part"
    for cam in image_00 image_01 image_02 image_03; do mv "$src/$cam" "$D1.part/$cam"; done
    mv "$D1.part" "$D1"
fi
if [ ! -d "$D0/velodyne_points/data" ]; then
    git --git-dir="$UDACITY" archive HEAD images/KITTI/2011_09_26 | tar -x -C "$tmp"
    mv "$tmp/images/KITTI/2011_09_26" "$D0.part" && mv "$D0.part" "$D0"
fi
echo "KITTI raw root: $RAW ($(ls "$D1/image_02/data" | wc -l) + $(ls "$D0/image_02/data" | wc -l) left frames)"

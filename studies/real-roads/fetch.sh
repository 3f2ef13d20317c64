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
fail() { echo "fetch.sh: error: $*" >&2; exit 2; }
# place DIR.part as DIR, refusing a DIR that is there but incomplete (never moved into it, never replaced)
place() {
    [ ! -e "$1" ] || fail "$1 exists but lacks $2: a copy cut short, or another drive; move it away and run again"
    mv -T "$1.part" "$1"
}
frames() { find "$1" -maxdepth 1 -name '*.png' | wc -l; }
mkdir -p "$DAY"
tmp=$(mktemp -d) && trap 'rm -rf "$tmp"' EXIT
if [ ! -d "$D1/image_03/data" ]; then
    git --git-dir="$SOFT" archive 0106406 code/data/DataSet1 | tar -x -C "$tmp"
    src=$tmp/code/data/DataSet1
    rm -rf "$D1.part" && mkdir -p "$D1.part"  # .part is this script's own: what an interrupted run left goes
    for cam in image_00 image_01 image_02 image_03; do mv -T "$src/$cam" "$D1.part/$cam"; done
    cp "$src"/calib_*.txt "$DAY/"
    place "$D1" image_03/data
fi
if [ ! -d "$D0/velodyne_points/data" ]; then
    git --git-dir="$UDACITY" archive HEAD images/KITTI/2011_09_26 | tar -x -C "$tmp"
    rm -rf "$D0.part"
    mv -T "$tmp/images/KITTI/2011_09_26" "$D0.part"
    place "$D0" velodyne_points/data
fi
for drive in "$D1" "$D0"; do  # what the study reads, checked before success is reported
    [ "$(frames "$drive/image_02/data")" -gt 0 ] || fail "$drive/image_02/data holds no frame; remove $drive and run again"
done
for f in calib_cam_to_cam.txt calib_velo_to_cam.txt; do
    [ -s "$DAY/$f" ] || fail "$DAY/$f is missing; remove $D1 and run again"
done
echo "KITTI raw root: $RAW ($(frames "$D1/image_02/data") + $(frames "$D0/image_02/data") left frames)"

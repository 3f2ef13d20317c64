"""Evaluation without a network: predictions and labels → scores and pictures.

* :mod:`freespace.evaluation.metrics`: confusion counts → Acc/Pre/Rec/F/IoU, the KITTI devkit's
  MaxF/AP/PRE/REC/FPR/FNR, :class:`~freespace.evaluation.metrics.RoadEvaluator`;
* :mod:`freespace.evaluation.bev`: the KITTI benchmark's bird's-eye-view transform;
* :mod:`freespace.evaluation.kitti`: ``freespace evaluate-kitti`` over folders of predictions;
* :mod:`freespace.evaluation.viz`: disparity colour maps, overlays, captioned grids, PR curves.

Never imports torch.
"""

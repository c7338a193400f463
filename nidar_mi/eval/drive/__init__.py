"""The drive study: odometry and intensity-aware place recognition on simulated drives.

* :mod:`.odometry`: ATE after SE(3) alignment (Umeyama) and the KITTI odometry devkit's
  relative error over fixed distances.
* :mod:`.scan_context`: Scan Context / Intensity Scan Context descriptors and their matching.
* :mod:`.loops`: loop-closure detection on a drive and its precision/recall.
* :mod:`.pose_graph`: pose-graph correction with the detected loops.
* :mod:`.drive_sweeps`: the sweeps of a drive, scanned and (for NIDAR) photographed along it by the
  trajectory renderer (:mod:`nidar_mi.sequence`), and read back.
* :mod:`.kiss`: KISS-ICP's odometry and registration on the sweeps.
* :mod:`.study`: the whole study (``python -m nidar_mi.drive``); :mod:`.report` its tables and
  figures.
"""

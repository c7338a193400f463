"""NIDAR: LiDAR intensity from RGB images.

Stages (one module each): ``stn`` (RGB -> pseudo-NIR, cs-stereo design, trained here on rendered
RGB/NIR pairs because the cs-stereo weights cannot be had), ``unet`` / ``aspp`` / ``heads`` /
``irnet`` (intrinsic decomposition R, S and the dense intensity head Î, with the paper's ablation
variants), ``losses``, ``data`` (training frames), ``frames`` (range compensation of the reported
intensity), ``loop`` / ``train`` (training), ``pipeline`` (inference end to end: the branch is
sampled at each point by :func:`nidar_mi.geometry.fusion.sample_cameras` and mapped by a sensor
profile of :mod:`nidar_mi.profiles`), ``model_io`` / ``checkpoint`` (safetensors only).
"""

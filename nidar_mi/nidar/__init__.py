"""NIDAR: LiDAR intensity from RGB images.

Stages (one module each): ``stn`` / ``stn_lowres`` (RGB -> pseudo-NIR: cs-stereo's design,
trained here on rendered RGB/NIR pairs because the cs-stereo weights cannot be had, and the
shipped low-resolution network trained on real photo pairs), ``unet`` / ``aspp`` / ``heads`` /
``irnet`` (intrinsic decomposition R, S and the dense intensity head Î, with the paper's ablation
variants), ``losses``, ``data`` / ``photo_data`` / ``preprocess`` (training frames and crops),
``config``, ``loop`` / ``train`` (training), ``infer`` / ``fold`` (inference on whole images),
``pipeline`` (inference end to end: the branch is sampled at each point by
:func:`nidar_mi.geometry.fusion.sample_cameras` and mapped by a sensor profile of
:mod:`nidar_mi.profiles`), ``model_io`` / ``checkpoint`` (safetensors
only).
"""

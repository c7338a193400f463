"""NIDAR: LiDAR intensity from RGB images.

Stages (one module each): ``stn`` (RGB -> pseudo-NIR, cs-stereo design, trained here on rendered
RGB/NIR pairs because the cs-stereo weights cannot be had), ``unet`` / ``aspp`` / ``heads`` /
``irnet`` (intrinsic decomposition R, S and the dense intensity head Î, with the paper's ablation
variants), ``losses``, ``data`` / ``frames`` (training frames), ``loop`` / ``train`` (training),
``calibration`` (distance encoding + quantile remapping), ``projection`` / ``cameras`` (point
assignment with an occlusion test), ``pipeline`` (inference end to end), ``model_io`` /
``checkpoint`` (safetensors only).
"""

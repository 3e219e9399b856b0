"""Registry entries of the learned (CNN) features.

Imported by :mod:`dmtrack.features.base` as a plug-in (``PLUGIN_MODULES``).  It imports neither PyTorch nor the
feature modules: the factories are ``"module:attribute"`` strings resolved when a feature is built.

=============  ===  ==========================================================================================
name           N    what
=============  ===  ==========================================================================================
``alexnet``    96   Caffe BVLC AlexNet conv1 + ReLU, stride 1, zero padding 5 (paper §2.1.2); user-supplied
                    weights (``bvlc_alexnet.caffemodel`` / ``bvlcalexnet-*.onnx`` / ``.npz``); torch optional
``alexnet64``  64   torchvision AlexNet conv1 + ReLU, stride 1, padding 5; user-supplied ``alexnet-owt-*.pth``
``siamese``    256  Zagoruyko–Komodakis "siam" descriptor of the 64×64 patch at every pixel; user-supplied
                    weights (authors' ``siam_*.bin`` / ``.npz``); torch optional (numpy is slow)
``tfeat``      128  TFeat descriptor of the 32×32 patch at every pixel; shipped weights; torch optional
``disk``       128  DISK U-Net dense descriptors; shipped weights; needs torch
=============  ===  ==========================================================================================

``alexnet-pcaK`` (and ``BASE-pcaK`` for any of these) are provided by the registry's PCA wrapper
(:mod:`dmtrack.features.pca`); AlexNet fuses the projection after conv1 (``compute_projected``).

Default scales: ``alexnet`` 1.23 and ``siamese`` 347.5 are the paper's values (its weights cannot be shipped, so
they cannot be recalibrated here); ``tfeat`` and ``disk`` were calibrated with
:func:`dmtrack.features.scale.compute_default_scales` on the same 20 sample frames as ``default_scales.json``
(target 130091.6 semi-dense pixels per frame, achieved 130091.4 and 130091.6); ``alexnet64`` is uncalibrated (1).
``tfeat`` and ``disk`` also carry their channel counts N_E and κ for ``channel_cost="balanced"``, measured on the
same frames (semi-dense pixels) with ``python -m dmtrack.features.scale --channels --features tfeat,disk FRAMES``
(docs/multichannel-cost.md); the values are in their entries below. The other learned features have none (the channel
mean is used).
"""

from __future__ import annotations

from dmtrack.features.base import register

_ENTRIES = (
    dict(
        name="alexnet",
        factory="dmtrack.features.alexnet:AlexNetFeature",
        channels=96,
        needs_colour=True,
        needs_weights=True,
        scale=1.23,
        description="Caffe BVLC AlexNet conv1 + ReLU at stride 1, zero padding 5 (BGR, ILSVRC mean), 96-D",
    ),
    dict(
        name="alexnet64",
        factory="dmtrack.features.alexnet:AlexNet64Feature",
        channels=64,
        needs_colour=True,
        needs_weights=True,
        description="torchvision AlexNet conv1 + ReLU at stride 1, zero padding 5 (RGB, ImageNet mean/std), 64-D",
    ),
    dict(
        name="siamese",
        factory="dmtrack.features.siamese:SiameseFeature",
        channels=256,
        needs_weights=True,
        scale=347.5,
        description="Zagoruyko-Komodakis 'siam' descriptor of the 64x64 patch at every pixel (dense), 256-D",
    ),
    dict(
        name="tfeat",
        factory="dmtrack.features.tfeat:TFeatFeature",
        channels=128,
        scale=29.3193,  # calibrated like default_scales.json (20 sample frames 0, 15, ..., 285; minUseGrad 5)
        energy_channels=31.516,  # N_E and κ at that scale, same frames, semi-dense pixels (measure_channel_statistics)
        info_channels=7.819,
        noise_energy_channels=3227.854,  # N_σ = N·noise_var/grey_noise_var = 128·182.752/7.247, same measurement
        description="TFeat (Liberty) descriptor of the 32x32 patch at every pixel (dense, shipped weights), 128-D",
    ),
    dict(
        name="disk",
        factory="dmtrack.features.disk:DiskFeature",
        channels=128,
        scale=8.3247,  # calibrated like default_scales.json (20 sample frames 0, 15, ..., 285; minUseGrad 5)
        energy_channels=24.032,  # N_E and κ at that scale, same frames, semi-dense pixels (measure_channel_statistics)
        info_channels=107.321,
        noise_energy_channels=150.202,  # N_σ = N·noise_var/grey_noise_var = 128·8.504/7.247, same measurement
        needs_colour=True,
        needs_torch=True,
        description="DISK U-Net dense descriptors at full resolution (shipped 'depth' weights), 128-D",
    ),
)

for _e in _ENTRIES:  # a module body runs once per process, so each name is registered once
    register(**_e)  # type: ignore[arg-type]

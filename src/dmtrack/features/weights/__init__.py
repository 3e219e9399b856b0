"""Pretrained weights of the learned features: where they live, how to read them, how to fetch them.

Locations
---------
A weight file is looked up, in this order, in

1. an explicit path (the feature's ``weights=`` option);
2. ``$DMTRACK_WEIGHTS`` (a directory), when set;
3. ``~/.cache/dmtrack/weights`` (:func:`user_weights_dir` when ``$DMTRACK_WEIGHTS`` is unset);
4. the package's own ``dmtrack/weights/`` directory, which ships the TFeat and DISK weights (see its
   ``PROVENANCE.md``).

The BVLC AlexNet and Zagoruyko–Komodakis "siam" weights cannot be shipped (licences, size); a missing file raises
:class:`~dmtrack.errors.InputError` naming the official URL and the directory to put it in. :func:`download`
fetches them (resumable, checksum-verified) on a machine with internet access::

    python -m dmtrack.features.weights download alexnet            # into $DMTRACK_WEIGHTS or ~/.cache/...
    python -m dmtrack.features.weights list

Readers (no PyTorch, Caffe, protobuf or ONNX package needed)
-----------------------------------------------------------
One table of formats (:data:`FORMATS`: per kind of weights its readers by file suffix, the expected arrays and
shapes, the conversion and where the format comes from) and one loader: :func:`load_weights` finds a catalogue
entry's file and reads it in the entry's format, :func:`read_weights` reads a given file in a named format.

* :func:`load_torch_file` – ``torch.save`` files, both the zip format (PyTorch ≥ 1.6) and the legacy pickle
  stream (TFeat's ``.params``, torchvision's ``alexnet-owt-7be5be79.pth``), through a restricted unpickler that
  only rebuilds tensors, dicts and lists (no code execution); tensors come back as numpy arrays.
* :func:`load_alexnet_conv1` – AlexNet conv1 from ``.caffemodel``, ``.onnx``, a torchvision state dict or ``.npz``.
* :func:`load_siamese` – the "siam" descriptor branch from the authors' binary ``.bin`` format or ``.npz``.
* :func:`load_tfeat`, :func:`load_disk` – the shipped networks' state dicts.

Modules: :mod:`~dmtrack.features.weights.catalogue` (known files, locations, checksums),
:mod:`~dmtrack.features.weights.download`, :mod:`~dmtrack.features.weights.torchfile` (the ``torch.save``
reader), :mod:`~dmtrack.features.weights.formats` (the table and the loader), :mod:`~dmtrack.features.weights.cli`.
"""

from __future__ import annotations

from dmtrack.features.weights.catalogue import (
    CATALOGUE,
    WEIGHTS_ENV,
    DownloadError,
    WeightFile,
    file_digest,
    find_weights,
    missing_weights_message,
    package_weights_dir,
    search_dirs,
    user_weights_dir,
    verify_checksum,
    weight_info,
)
from dmtrack.features.weights.cli import main
from dmtrack.features.weights.download import download
from dmtrack.features.weights.formats import (
    CAFFE_BGR_MEAN,
    FORMATS,
    SIAM_SHAPES,
    TFEAT_SHAPES,
    TORCHVISION_MEAN,
    TORCHVISION_STD,
    Conv1Weights,
    WeightFormat,
    load_alexnet_conv1,
    load_disk,
    load_siamese,
    load_tfeat,
    load_weights,
    read_weights,
    weight_format,
)
from dmtrack.features.weights.torchfile import load_state_dict, load_torch_file

__all__ = [
    "CAFFE_BGR_MEAN",
    "CATALOGUE",
    "FORMATS",
    "SIAM_SHAPES",
    "TFEAT_SHAPES",
    "TORCHVISION_MEAN",
    "TORCHVISION_STD",
    "WEIGHTS_ENV",
    "Conv1Weights",
    "DownloadError",
    "WeightFile",
    "WeightFormat",
    "download",
    "file_digest",
    "find_weights",
    "load_alexnet_conv1",
    "load_disk",
    "load_siamese",
    "load_state_dict",
    "load_tfeat",
    "load_torch_file",
    "load_weights",
    "main",
    "missing_weights_message",
    "package_weights_dir",
    "read_weights",
    "search_dirs",
    "user_weights_dir",
    "verify_checksum",
    "weight_format",
    "weight_info",
]

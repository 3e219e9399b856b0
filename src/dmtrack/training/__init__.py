"""Training of the learned ``tracknet`` feature through the tracker's own objective (issue 15).

* :mod:`~dmtrack.training.alignment` — the tracker's per-level objective (residuals, weights, Jacobians, normal
  equations, the damped Gauss–Newton step) in PyTorch, differentiable;
* :mod:`~dmtrack.training.model` — the network (:class:`~dmtrack.training.model.TrackNet`) and its ``.npz`` export;
* :mod:`~dmtrack.training.train` — the training loop (synthetic pairs, unrolled steps, loss on the final pose);
* :mod:`~dmtrack.training.cli` — ``dmtrack train-feature``.

Needs PyTorch (``pip install 'dmtrack[learned]'``); nothing here is imported by ``import dmtrack``. The inference
without PyTorch is :mod:`dmtrack.features.tracknet`.
"""

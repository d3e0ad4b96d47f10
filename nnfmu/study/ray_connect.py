"""Connecting to Ray: a local instance, or a running cluster, including one bound to the loopback address.

Ray rewrites a loopback cluster address (``127.0.0.1:PORT``, ``localhost:PORT``)
into this machine's network address before it connects
(``ray._private.services.resolve_ip_for_localhost``), and registers the driver
under that address too. A cluster whose nodes were started on 127.0.0.1 (``ray
start --node-ip-address 127.0.0.1``, or ``ray.cluster_utils.Cluster`` with
``node_ip_address="127.0.0.1"``) listens there only, so the driver waited for
its GCS forever (13 minutes measured before giving up; issue 12).
:func:`connect` checks first whether the cluster answers on the loopback
address; if it does, it connects there and registers the driver as 127.0.0.1.
An address where nothing answers is one clear error instead of a hang.

Without an address, :func:`ray_session` starts a local instance of its own (``ray.init(address="local")``) even where
a cluster runs on this machine (``ray start``, or ``RAY_ADDRESS`` set): ``ray.init()`` would join that cluster, and
with ``num_cpus`` given it refused to (``ValueError: When connecting to an existing cluster, num_cpus and num_gpus
must not be provided``). ``--address`` is how nnfmu joins a cluster.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
from unittest import mock

from nnfmu.errors import ConfigError, NnfmuError

LOOPBACK = ("127.0.0.1", "localhost", "::1")
_PROBE_SECONDS = 5.0


class MissingExtraError(NnfmuError, ImportError):
    """An optional dependency (an extra of the nnfmu package) is not installed."""


def require_ray():
    """Import Ray Tune, or raise :class:`MissingExtraError` naming the extra to install."""
    try:
        import ray
        from ray import tune
    except ImportError as exc:
        raise MissingExtraError(
            f"hyperparameter search needs Ray Tune, which is not installed ({exc}); install the optional extra "
            "with: pip install \"nnfmu[tune]\" (or pip install \"ray[tune]\")"
        ) from exc
    return ray, tune


def split_address(address: str) -> tuple[str, int]:
    """``"ray://host:port"`` or ``"host:port"`` -> ``(host, port)``; ConfigError for anything else."""
    bare = address.split("://", 1)[-1]
    host, sep, port = bare.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ConfigError(f"Ray address {address!r} is not HOST:PORT; give the address 'ray start --head' printed, "
                          "e.g. 127.0.0.1:6379")
    return host.strip("[]"), int(port)


def _answers(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=_PROBE_SECONDS):
            return True
    except OSError:
        return False


def connect(ray, address: str) -> None:
    """``ray.init`` against the cluster at ``address`` (see the module docstring for loopback clusters)."""
    host, port = split_address(address)
    if host in LOOPBACK and _answers("127.0.0.1", port):
        from ray._private import services

        keep_loopback = lambda h: "127.0.0.1" if h in LOOPBACK else h  # noqa: E731
        with mock.patch.object(services, "resolve_ip_for_localhost", keep_loopback):
            ray.init(address=f"127.0.0.1:{port}", _node_ip_address="127.0.0.1", log_to_driver=False)
        return
    if not address.startswith("ray://") and not _answers(host, port):
        raise ConfigError(f"no Ray cluster answers at {address}; start one with 'ray start --head' and pass the "
                          "address it prints, or drop --address to use a local Ray instance")
    ray.init(address=address, log_to_driver=False)


def _keep_loopback(host: str) -> str:
    return "127.0.0.1" if host in LOOPBACK else host


@contextlib.contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None, num_gpus: float | None = None,
                quiet: bool = False, cuda_visible: str | None = None):
    """Connect to the cluster at ``address`` or start a local Ray instance; stop what was started here.

    ``quiet``: a local instance logs warnings and errors only (not "Started a local Ray instance").
    ``cuda_visible``: the ``CUDA_VISIBLE_DEVICES`` a local instance starts with, e.g. ``"1"`` for
    ``--device cuda:1``: Ray then hands out that GPU alone (seen as ``cuda:0`` in a task)."""
    ray, _ = require_ray()
    started = False
    if not ray.is_initialized():
        if address:
            connect(ray, address)
        else:  # a local instance listens on the loopback address only, as a loopback cluster does (see connect)
            from ray._private import services

            gpus = {} if cuda_visible is None else {"CUDA_VISIBLE_DEVICES": cuda_visible}
            with mock.patch.object(services, "resolve_ip_for_localhost", _keep_loopback), \
                    mock.patch.dict(os.environ, gpus):
                ray.init(address="local", num_cpus=num_cpus or os.cpu_count(), num_gpus=num_gpus,
                         include_dashboard=False, log_to_driver=False, _node_ip_address="127.0.0.1",
                         logging_level=logging.WARNING if quiet else logging.INFO)
        started = True
    try:
        yield ray
    finally:
        if started:
            ray.shutdown()

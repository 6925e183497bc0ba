"""Scans on a Dask cluster: connecting within a stated bound, and running chunks as tasks.

On a GPU scan every worker runs its chunks on a GPU of its own, as
dask-cuda's ``LocalCUDACluster`` gives each worker one (there by
``CUDA_VISIBLE_DEVICES``): when the scan starts, the workers on each host
are numbered (:func:`gpu_places`), and each chunk task runs on device
``number mod GPUs`` of its worker's host (``dicetrace.core.gpu.only_device``),
so that workers use distinct GPUs as long as a host has no more workers than
GPUs; where it has more, those on one GPU split its memory.  A worker that
sees one GPU only (a dask-cuda worker) uses that one.  Every chunk runs the
same kernels from its own ICs: the rows are those of a one-GPU run.
"""

from __future__ import annotations

import itertools
import os
import socket
import threading
import time
import uuid
from collections.abc import Iterable, Iterator

import pyarrow as pa

from dicetrace.devices import device_label, gpu_unavailable_reason, resolve_device
from dicetrace.extras import require
from dicetrace.scan.definition import ScanDefinition, device_kind

from dicetrace.scan.folder import _chunk_task

#: Longest wait for a Dask scheduler to answer, s (the message of a failed connection states it).
DASK_CONNECT_TIMEOUT_S = 10.0


class SchedulerError(ConnectionError):
    """The Dask scheduler could not be reached, or is not one."""


def _check_dask(dask) -> None:
    if dask is not None and dask is not False:
        require("dask", "a scan on Dask")
    if dask is None or isinstance(dask, bool) or isinstance(dask, str):
        if isinstance(dask, str):
            check_scheduler_address(dask)
        return
    try:
        from dask.distributed import Client  # dask.distributed is slow to import: only for a Dask run
    except ImportError:  # pragma: no cover
        Client = ()
    if not isinstance(dask, Client):
        raise TypeError(f"dask must be None, True, a scheduler address or a dask.distributed.Client, not {type(dask).__name__}")


_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")


def check_scheduler_address(address: str) -> tuple[str, str, int | None]:
    """(scheme, host, port) of a Dask scheduler address, or ValueError naming it."""
    if not isinstance(address, str):
        raise TypeError(f"the scheduler address must be a string, not {type(address).__name__}")
    text = address.strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    bad = ValueError(f"scheduler address {address!r} is not SCHEME://HOST:PORT (e.g. tcp://127.0.0.1:8786)")
    if scheme not in _SCHEMES or not rest or any(c.isspace() for c in rest) or "/" in rest:
        raise bad
    if scheme == "inproc":
        return scheme, rest, None
    if rest.startswith("["):  # [IPv6]:port
        host, _, port_text = rest[1:].partition("]")
        port_text = port_text[1:] if port_text.startswith(":") else port_text
    else:
        host, _, port_text = rest.rpartition(":") if ":" in rest else (rest, "", "")
    if not host:
        raise bad
    if not port_text:
        raise ValueError(f"scheduler address {address!r} needs a port (e.g. {scheme}://{host}:8786)")
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise bad
    return scheme, host, int(port_text)


def _connect(address: str, timeout: float):
    """A Client of the scheduler at ``address``, within ``timeout`` seconds, or :class:`SchedulerError`."""
    from dask.distributed import Client  # dask.distributed is slow to import: only for a Dask run

    scheme, host, port = check_scheduler_address(address)
    deadline = time.monotonic() + timeout
    if scheme in ("tcp", "tls") and port is not None:
        try:
            with socket.create_connection((host, port), timeout=timeout):
                pass
        except OSError as e:
            why = "timed out" if isinstance(e, TimeoutError) else (e.strerror or str(e))
            raise SchedulerError(
                f"cannot reach the Dask scheduler at {address!r} within {timeout:g} s: {why}"
            ) from None
    last = None
    for _attempt in range(2):
        left = deadline - time.monotonic()
        if left <= 0.5:
            break
        try:
            return _client_within(Client, address, left, timeout)
        except AssertionError as e:
            # distributed's handshake can trip when the scheduler is still winding
            # down another client's futures: try again, within the same deadline.
            last = e
            time.sleep(min(0.5, max(0.0, deadline - time.monotonic() - 0.5)))
        except SchedulerError:
            raise
        except OSError as e:
            raise SchedulerError(
                f"no answer from the Dask scheduler at {address!r} within {timeout:g} s "
                f"({' '.join(str(e).split())[:160]})"
            ) from None
        except Exception as e:  # noqa: BLE001 - a server that is not a Dask scheduler fails in many ways
            raise SchedulerError(
                f"{address!r} does not answer as a Dask scheduler (the handshake failed: "
                f"{type(e).__name__}: {' '.join(str(e).split())[:160]})"
            ) from None
    raise SchedulerError(f"the Dask scheduler at {address!r} did not complete the handshake within {timeout:g} s"
                         + (f" ({type(last).__name__})" if last is not None else ""))


def _client_within(Client, address: str, left: float, timeout: float):
    """``Client(address)``, given at most ``left`` seconds: distributed's own timeout does not cover a
    server that accepts the connection and then says nothing, so the handshake runs in a thread."""
    box: dict = {}

    def make() -> None:
        try:
            box["client"] = Client(address, timeout=left)
        except BaseException as e:  # noqa: BLE001 - handed to the caller
            box["error"] = e

    th = threading.Thread(target=make, name="dicetrace-dask-connect", daemon=True)
    th.start()
    th.join(left + 0.5)
    if th.is_alive():
        raise SchedulerError(f"no answer from the Dask scheduler at {address!r} within {timeout:g} s "
                             "(the server accepted the connection but did not complete the handshake)")
    if "error" in box:
        raise box["error"]
    return box["client"]


def local_worker_count(n_workers: int | None, device: str = "cpu") -> int:
    """The worker processes of a local cluster: ``n_workers`` where given, else one per GPU for a scan on a GPU
    (``device``: cpu, cuda, auto or a device label such as ``cuda:0 (…)``, as it resolves on this machine), else
    one per CPU core."""
    if n_workers:
        return n_workers
    if device != "cpu" and resolve_device(device_kind(device) if device != "auto" else device).gpu:
        from dicetrace.core import gpu  # numba-cuda: imported only for a GPU scan

        return max(1, gpu.device_count())
    return os.cpu_count() or 1


def _open_dask(dask, n_workers, timeout: float | None = None, device: str = "cpu"):
    """(client, closers) for ``dask``: True (a LocalCluster of :func:`local_worker_count` workers for ``device``),
    an address (within ``timeout``, default ``DASK_CONNECT_TIMEOUT_S``), or a Client."""
    from dask.distributed import Client, LocalCluster  # dask.distributed is slow to import: only for a Dask run

    if isinstance(dask, Client):
        return dask, []
    if isinstance(dask, str):
        client = _connect(dask, DASK_CONNECT_TIMEOUT_S if timeout is None else timeout)
        return client, [client]
    try:
        cluster = LocalCluster(
            n_workers=local_worker_count(n_workers, device), threads_per_worker=1, processes=True,
            dashboard_address=":0"
        )
    except Exception as e:  # noqa: BLE001
        raise SchedulerError(f"could not start a local Dask cluster: {type(e).__name__}: {' '.join(str(e).split())[:160]}") from None
    client = Client(cluster)
    return client, [client, cluster]


def _device_task(device: str) -> str:
    """A Dask task: where ``device`` runs on the worker that runs it (``dicetrace.devices.device_label``)."""
    return device_label(resolve_device(device))


def worker_device(client, device: str) -> str:
    """The device ``device`` (cpu, cuda, auto) is on the cluster's workers, as one of them resolves it.

    A :class:`~dicetrace.devices.DeviceError` where that worker has no GPU
    for ``"cuda"``.  Every chunk task resolves the scan's device again on its
    own worker and refuses a device other than the scan's.
    """
    fut = client.submit(_device_task, device, key=f"dicetrace-device-{uuid.uuid4().hex[:8]}", pure=False)
    try:
        return fut.result()
    finally:
        fut.release()


def gpu_places(client) -> dict[str, tuple[int, int]]:
    """Worker address → (its number among the workers of its host, how many workers the host has).

    Workers are numbered by name (LocalCluster's 0, 1, 2, … in order), then address.
    """
    try:
        workers = client.scheduler_info(n_workers=-1)["workers"]
    except TypeError:  # a distributed without n_workers: it lists them all
        workers = client.scheduler_info()["workers"]
    hosts: dict[str, list] = {}
    for addr, info in workers.items():
        name = info.get("name", addr)
        key = (0, name, addr) if isinstance(name, int) else (1, str(name), addr)
        hosts.setdefault(str(info.get("host", addr)), []).append((key, addr))
    places = {}
    for members in hosts.values():
        for i, (_key, addr) in enumerate(sorted(members)):
            places[addr] = (i, len(members))
    return places


def _gpu_of(place: tuple[int, int], ndev: int) -> tuple[int, float]:
    """(device, share of its memory) of the worker at ``place`` on a host whose workers see ``ndev`` GPUs."""
    i, n = place
    k = i % ndev
    return k, 1.0 / max(1, len(range(k, n, ndev)))


def _gpu_chunk_task(defn_dict: dict, c: int, threads: int | None, places: dict) -> tuple[int, pa.Table]:
    """A Dask task: chunk ``c`` of a GPU scan, on this worker's own GPU (:func:`gpu_places`)."""
    from dask.distributed import get_worker  # dask.distributed is slow to import: only for a Dask run

    if gpu_unavailable_reason() is not None:  # a worker without a GPU: the chunk refuses, saying why
        return _chunk_task(defn_dict, c, threads)
    from dicetrace.core import gpu  # numba-cuda: optional, imported only for a GPU run

    worker = get_worker()
    # a worker that joined after the scan started: numbered by its name where it is a number
    place = places.get(worker.address) or (worker.name if isinstance(worker.name, int) else 0, 1)
    k, share = _gpu_of(place, gpu.device_count())
    with gpu.only_device(k, share):
        return _chunk_task(defn_dict, c, threads)


def _iter_dask(defn: ScanDefinition, todo: Iterable[int], client, threads) -> Iterator[tuple[int, pa.Table]]:
    """Chunks on a Dask cluster as they complete, with a bounded number of tasks in flight; a GPU scan's on
    each worker's own GPU (:func:`_gpu_chunk_task`)."""
    from dask.distributed import as_completed  # dask.distributed is slow to import: only for a Dask run

    d = defn.to_dict()
    run = uuid.uuid4().hex[:8]
    task, places = (_chunk_task, ()) if defn.device == "cpu" else (_gpu_chunk_task, (gpu_places(client),))
    try:
        width = max(4, 2 * sum(client.nthreads().values()))
    except Exception:  # noqa: BLE001
        width = 16
    it = iter(todo)

    def submit(c):
        return client.submit(task, d, c, threads or 1, *places, key=f"dicetrace-scan-{run}-{c}", pure=False)

    live = {submit(c) for c in itertools.islice(it, width)}
    try:
        ac = as_completed(list(live))
        for fut in ac:
            c, table = fut.result()
            live.discard(fut)
            fut.release()
            nxt = next(it, None)
            if nxt is not None:
                f2 = submit(nxt)
                live.add(f2)
                ac.add(f2)
            yield c, table
    finally:
        for f in live:
            f.cancel()



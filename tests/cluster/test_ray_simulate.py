"""``simulate --ray`` on a private local Ray instance: the same dataset as the local run, through a killed
worker and a restart, loopback only, and one-line errors (extra ``ray``)."""

import importlib.util
import ipaddress
import os
import signal
import threading

import numpy as np
import pytest
from checks import assert_one_line_error

if importlib.util.find_spec("ray") is None:  # not imported here: ray_session sets its environment before import
    pytest.skip("the 'ray' extra is not installed", allow_module_level=True)
psutil = pytest.importorskip("psutil", reason="the 'ray' extra (psutil) is not installed")

from tactile_manip.cli import main  # noqa: E402
from tactile_manip.cluster.blocks import blocks_folder  # noqa: E402
from tactile_manip.cluster.connect import check_workers_import, ray_session  # noqa: E402
from tactile_manip.cluster.simulate import generate_on_ray  # noqa: E402
from tactile_manip.errors import ClusterError  # noqa: E402
from tactile_manip.sim.dataset import generate, load_dataset_config  # noqa: E402

pytestmark = [pytest.mark.ray, pytest.mark.slow]


@pytest.fixture(scope="module")
def cfg():
    return load_dataset_config("configs/dataset/supermag.toml").scaled(0.005)


@pytest.fixture(scope="module")
def local(cfg):
    return generate(cfg, workers=1)


def _same(a, b):
    assert a.fingerprint() == b.fingerprint()
    assert sorted(a.extras) == sorted(b.extras)
    for k in a.extras:
        np.testing.assert_array_equal(a.extras[k], b.extras[k], err_msg=k)


def test_ray_run_equals_the_local_run(cfg, local, tmp_path):
    seen = []
    data = generate_on_ray(cfg, tmp_path / "d.npz", num_cpus=2, block_size=7, progress=seen.append)
    _same(data, local)
    assert sum(seen) == len(local)
    assert data.provenance["ray"]["blocks"] == -(-len(local) // 7)


def test_a_killed_worker_block_is_retried(cfg, local, tmp_path):
    killed = []
    stop = threading.Event()

    def killer():
        while not stop.is_set() and not killed:
            for p in psutil.process_iter(["name", "cmdline"]):
                title = " ".join(p.info["cmdline"] or []) + " " + (p.info["name"] or "")
                if "simulate_block" in title and p.pid != os.getpid():
                    try:
                        os.kill(p.pid, signal.SIGKILL)
                        killed.append(p.pid)
                    except ProcessLookupError:
                        continue
                    break
            stop.wait(0.02)

    thread = threading.Thread(target=killer, daemon=True)
    thread.start()
    try:
        data = generate_on_ray(cfg, tmp_path / "d.npz", num_cpus=2, block_size=len(local) // 2 + 1)
    finally:
        stop.set()
        thread.join()
    assert killed, "no worker was running a block to kill"
    _same(data, local)


def test_a_restarted_run_keeps_its_finished_blocks(cfg, local, tmp_path):
    out = tmp_path / "d.npz"
    done = []

    def interrupt_after_first_block(n):
        done.append(n)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        generate_on_ray(cfg, out, num_cpus=2, block_size=7, progress=interrupt_after_first_block)
    kept = sorted(blocks_folder(out).glob("block-*.npz"))
    assert len(kept) == 1
    data = generate_on_ray(cfg, out, num_cpus=2, block_size=7)
    assert data.provenance["ray"]["blocks_resumed"] == 1
    _same(data, local)


def test_private_instance_listens_on_loopback_only_and_checks_worker_imports():
    with ray_session(None, num_cpus=1) as ray:
        assert check_workers_import(ray, "tactile_manip")
        with pytest.raises(ClusterError, match="cannot import tactile_manip_missing_pkg"):
            check_workers_import(ray, "tactile_manip_missing_pkg")
        me = psutil.Process()
        pids = {me.pid} | {c.pid for c in me.children(recursive=True)}
        listening = sorted({(c.laddr.ip, c.laddr.port) for c in psutil.net_connections(kind="inet")
                            if c.status == psutil.CONN_LISTEN and c.pid in pids})
    print("listening:", listening)  # the record (pytest -s shows it); docs/cluster.md lists the ports
    assert listening, "found no listening socket of the Ray instance"
    outside = [(ip, port) for ip, port in listening if not _loopback(ip)]
    assert not outside, f"the private Ray instance listens beyond loopback: {outside}"


def _loopback(ip: str) -> bool:
    addr = ipaddress.ip_address(ip.split("%")[0])
    mapped = getattr(addr, "ipv4_mapped", None)
    return (mapped or addr).is_loopback


def test_cli_unreachable_address_is_one_line_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "d.npz"
    assert main(["simulate", "--scale", "0.005", "--ray", "127.0.0.1:9", "--out", str(out)]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", "cannot reach the Ray cluster at 127.0.0.1:9")
    assert not out.exists() and not blocks_folder(out).exists()


@pytest.mark.parametrize("argv, message", [
    (["--ray", "nonsense"], "expected 'local', 'auto', HOST:PORT"),
    (["--ray", "--block-size", "0"], "--block-size must be >= 1"),
    (["--block-size", "4"], "--block-size applies to --ray runs only"),
])
def test_cli_bad_ray_options(tmp_path, capsys, argv, message):
    out = tmp_path / "d.npz"
    assert main(["simulate", "--scale", "0.005", "--out", str(out), *argv]) == 2
    assert_one_line_error(capsys.readouterr().err, "simulate", message)
    assert not out.exists()


def test_cli_ray_run_written_as_shards_has_the_local_fingerprint(local, tmp_path):
    from tactile_manip.data import ShardedDataset

    out = tmp_path / "D"
    assert main(["simulate", "--scale", "0.005", "--ray", "--workers", "2", "--shard-size", "16",
                 "--out", str(out)]) == 0
    sharded = ShardedDataset(out)
    assert sharded.shard_count == -(-len(local) // 16)
    assert sharded.fingerprint() == local.fingerprint()
    assert not blocks_folder(out).exists()

"""The Python module against the command line: the same frames as `volreel decode`, the same
metrics as `volreel compare`, encodes from arrays and generators, and clear exceptions for bad
input. Run by ctest with PYTHONPATH at build/python and VOLREEL_CLI naming the volreel program."""

import _thread
import json
import os
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pathlib

import numpy as np
import pytest

import volreel

CLI = os.environ["VOLREEL_CLI"]


def run(*args, cwd=None):
    return subprocess.run([CLI, *map(str, args)], check=True, capture_output=True, text=True,
                          cwd=cwd).stdout


def read_f32(path, dims):
    x, y, z = dims
    return np.fromfile(path, dtype="<f4").reshape(z, y, x)


def sequence_psnr(original, decoded):
    original = np.asarray(original, dtype=np.float64)
    mse = np.mean((original - np.asarray(decoded, dtype=np.float64)) ** 2)
    value_range = original.max() - original.min()
    return 10 * np.log10(value_range ** 2 / mse)


@pytest.fixture(scope="module")
def series(tmp_path_factory):
    """A 40x36x24 series of 6 frames (a non-cube) written by volreel gen."""
    d = tmp_path_factory.mktemp("series")
    run("gen", "analytic", "--field", "blobs", "--dims", "40x36x24", "--frames", "6",
        "--out", d / "s")
    meta = json.loads((d / "s" / "series.json").read_text())
    frames = np.stack([read_f32(d / "s" / f, meta["dims"]) for f in meta["frames"]])
    return d / "s", meta, frames


@pytest.fixture(scope="module")
def container(series, tmp_path_factory):
    path, _, _ = series
    out = tmp_path_factory.mktemp("container") / "c.vreel"
    # Bricks of 36^3: two levels on this small volume (the chosen size would make it one brick).
    run("encode", path, "--out", out, "--psnr", "45", "--atoms", "64", "--brick-size", "36")
    return out


def test_opens_with_the_manifest_attributes(series, container):
    _, meta, frames = series
    c = volreel.open(container)
    assert c.dims == tuple(meta["dims"])
    assert c.shape == (6, 24, 36, 40)
    assert c.frames == len(c) == 6
    assert c.times == pytest.approx(meta["timestamps"])
    assert c.levels >= 1
    lo, hi = c.value_range
    assert lo == pytest.approx(frames.min()) and hi == pytest.approx(frames.max())
    info = c.info()
    assert info["bps"] == pytest.approx(c.bps)
    assert c.bps == pytest.approx(8 * info["total_bytes"] / (40 * 36 * 24 * 6))
    assert info["dims"] == list(meta["dims"])
    assert "c.vreel" in repr(c)


def test_frames_are_those_of_volreel_decode(container, tmp_path):
    c = volreel.open(container)
    for t in (0, 3, 5):
        for level in range(c.levels):
            out = tmp_path / f"f{t}_{level}.f32"
            run("decode", container, "--frame", t, "--level", level, "--out", out)
            expected = read_f32(out, c.level_dims(level))
            got = c.frame(t, level=level)
            assert got.dtype == np.float32 and got.shape == expected.shape
            assert np.array_equal(got, expected), (t, level)
    # Into an array given, reused from step to step.
    buffer = np.full((24, 36, 40), np.nan, dtype=np.float32)
    assert c.frame(3, out=buffer) is buffer
    assert np.array_equal(buffer, c.frame(3))
    with pytest.raises(ValueError, match="out: expected"):
        c.frame(3, out=np.empty((24, 36, 40), dtype=np.float64))
    with pytest.raises(ValueError, match="out: expected"):
        c.frame(3, level=0, out=buffer)
    # The finest level by default, negative indices from the end.
    assert np.array_equal(c.frame(5), c.frame(-1, level=c.levels - 1))


def test_a_frame_file_cut_short_while_open_is_an_error_not_a_crash(container, tmp_path):
    """Frame files are read, not memory-mapped: a file cut short under an open container (a
    re-encode in place, a full disk) gave SIGBUS to a mapped reader, killing Python."""
    copy = tmp_path / "c.vreel"
    shutil.copytree(container, copy)
    c = volreel.open(copy)
    before = c.frame(1)
    frame = sorted((copy / "frames").iterdir())[1]
    os.truncate(frame, 0)
    # The frame read before is held; read again, it is named as cut short.
    np.testing.assert_array_equal(c.frame(1), before)
    with pytest.raises(volreel.FormatError, match=frame.name):
        volreel.open(copy).frame(1)


def test_a_forked_child_decodes_after_its_parent_did(container):
    """GNU OpenMP's threads do not survive fork(): a child that entered a parallel region after
    its parent had waited for ever (multiprocessing's workers on Linux)."""
    c = volreel.open(container)
    expected = c.frame(1)
    pid = os.fork()
    if pid == 0:
        ok = False
        try:
            ok = np.array_equal(volreel.open(container).frame(1), expected)
        finally:
            os._exit(0 if ok else 1)
    deadline = time.monotonic() + 60
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, 9)
            os.waitpid(pid, 0)
            pytest.fail("the forked child's decode did not finish in 60 s")
        time.sleep(0.05)
    assert os.waitstatus_to_exitcode(status) == 0


def test_iteration_and_indexing(series, container):
    _, _, frames = series
    c = volreel.open(container)
    all_frames = list(c)
    assert len(all_frames) == 6
    assert np.array_equal(all_frames[2], c[2])
    assert np.array_equal(c[-1], c[5])
    assert [f.shape for f in c[1:5:2]] == [(24, 36, 40)] * 2
    decoded = np.stack(all_frames)
    assert sequence_psnr(frames, decoded) >= 45 - 0.05


def test_a_path_object_huge_indices_and_close(container):
    # pathlib.Path opens as str does (volreel.open and Container alike).
    c = volreel.Container(Path(container))
    assert c.location == volreel.open(str(container)).location
    # An index beyond int64 is out of range, as any other (not a TypeError about the signature);
    # numpy's integers are indices.
    for t in (2**70, -(2**70)):
        with pytest.raises(IndexError, match=f"frame {t} is out of range"):
            c.frame(t)
    with pytest.raises(IndexError, match=f"level {2**80} is out of range"):
        c.frame(0, level=2**80)
    with pytest.raises(IndexError, match=f"level {-(2**80)} is out of range"):
        c.level_dims(-(2**80))
    assert np.array_equal(c.frame(np.int64(1)), c.frame(1))
    with pytest.raises(TypeError):
        c.frame(1.5)
    with pytest.raises(TypeError, match="location: expected"):
        volreel.Container(b"c.vreel")
    # close() lets go of the frames and files; the manifest's properties stay; `with` closes.
    with volreel.open(container) as d:
        assert not d.closed and d.frame(0).shape == c.frame(0).shape
    assert d.closed and d.dims == c.dims and d.frames == c.frames and d.bps == c.bps
    with pytest.raises(ValueError, match="is closed"):
        d.frame(0)
    d.close()  # again: nothing to do


def test_bad_input_raises_with_the_library_message(container, tmp_path):
    with pytest.raises(volreel.FormatError, match="nothing.vreel"):
        volreel.open(tmp_path / "nothing.vreel")
    with pytest.raises(ValueError, match="unsupported scheme"):
        volreel.open("ftp://example.org/c.vreel")
    c = volreel.open(container)
    with pytest.raises(IndexError, match="out of range"):
        c.frame(6)
    with pytest.raises(IndexError, match="level"):
        c.frame(0, level=c.levels)
    # A damaged frame: a byte flipped in the last frame file's payload.
    damaged = tmp_path / "damaged.vreel"
    shutil.copytree(container, damaged)
    frame = sorted((damaged / "frames").iterdir())[-1]
    data = bytearray(frame.read_bytes())
    data[len(data) // 2] ^= 0xFF
    frame.write_bytes(bytes(data))
    with pytest.raises(volreel.FormatError, match=frame.name):
        volreel.open(damaged).frame(5)
    # Input that cannot be encoded.
    bad = np.zeros((3, 8, 8, 8), dtype=np.float32)
    bad[2, 1, 2, 3] = np.nan
    with pytest.raises(volreel.InputError, match=r"frames\[2\].*\[1, 2, 3\].*not finite"):
        volreel.encode(bad, tmp_path / "nan.vreel", codec="zfp")
    assert not (tmp_path / "nan.vreel").exists()
    with pytest.raises(volreel.InputError, match=r"frames\[2\].*\[1, 2, 3\].*not finite"):
        volreel.encode(iter(bad), tmp_path / "nan.vreel", codec="zfp")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged.vreel"]
    with pytest.raises(ValueError, match="t, z, y, x"):
        volreel.encode(np.zeros((8, 8)), tmp_path / "flat.vreel")
    with pytest.raises(ValueError, match="at most one"):
        volreel.encode(np.zeros((2, 8, 8, 8)), tmp_path / "x.vreel", psnr=40, bps=1)
    with pytest.raises(ValueError, match="same shape"):
        volreel.psnr(np.zeros((4, 4)), np.zeros((4, 5)))
    with pytest.raises(ValueError, match=r"shape \[0, 8, 8, 8\] holds no value"):
        volreel.encode(np.zeros((0, 8, 8, 8), np.float32), tmp_path / "empty.vreel", codec="zfp")
    with pytest.raises(ValueError, match="max_keyframe_gap must be in 1..65535"):
        volreel.encode(np.zeros((2, 8, 8, 8)), tmp_path / "x.vreel", max_keyframe_gap=0)
    # What `volreel encode` refuses on its command line, refused alike, before anything is written.
    zeros = np.zeros((2, 8, 8, 8), np.float32)
    for kwargs, message in [
        ({"psnr": -5}, "psnr must be a finite number > 0"),
        ({"psnr": 0}, "psnr must be a finite number > 0"),
        ({"psnr": float("inf")}, "psnr must be a finite number > 0"),
        ({"bps": -1}, "bps must be a finite number > 0"),
        ({"codec": "zfp", "psnr": 40}, "psnr applies to the ksvd codec"),
        ({"codec": "zfp", "bps": 2}, "bps applies to the ksvd codec"),
        ({"codec": "zfp", "dictionary": "dct"}, "dictionary applies to the ksvd codec"),
        ({"codec": "zfp", "atoms": 128}, "atoms applies to the ksvd codec"),
        ({"zfp_accuracy": 0.01}, 'zfp_accuracy applies to codec="zfp" only'),
        ({"codec": "zfp", "zfp_accuracy": 0}, "zfp_accuracy must be a finite number > 0"),
        ({"atoms": -1}, r"atoms must be 0 \(try the sizes and keep the best\) or 1..65536, not -1"),
        ({"overwrite": True, "resume": True}, "overwrite and resume exclude each other"),
        ({"dictionary": "dct", "atoms": 128}, "give dictionary or atoms, not both"),
    ]:
        with pytest.raises(ValueError, match=message):
            volreel.encode(zeros, tmp_path / "x.vreel", **kwargs)
    assert not (tmp_path / "x.vreel").exists()
    # A brick size as a number and a dictionary as a path, as `out` may be one.
    small = np.random.default_rng(1).random((2, 20, 20, 20), dtype=np.float32)
    s = volreel.encode(small, tmp_path / "b.vreel", dictionary=Path("dct"), brick_size=12,
                       spacing=(0.5, 1, 4))
    assert s["frames"] == 2 and volreel.open(tmp_path / "b.vreel").info()["brick_size"] == 12
    assert volreel.open(tmp_path / "b.vreel").spacing == (0.5, 1.0, 4.0)
    with pytest.raises(volreel.InputError, match="spacing: expected three positive finite"):
        volreel.encode(small, tmp_path / "x.vreel", dictionary="dct", spacing=(1, 0, 1))
    assert not (tmp_path / "x.vreel").exists()
    shutil.rmtree(tmp_path / "b.vreel")
    # Levels count from the finest when negative, in frame() and level_dims() alike.
    assert c.level_dims(-1) == c.dims and c.level_dims(-c.levels) == c.level_dims(0)
    with pytest.raises(IndexError, match=r"level -5 is out of range"):
        c.level_dims(-5)
    with pytest.raises(IndexError, match=r"level -5 is out of range"):
        c.frame(0, level=-5)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damaged.vreel"]
    # A folder of other files is no container to write into.
    data = tmp_path / "data"
    data.mkdir()
    bad[:2].tofile(data / "000000.f32")
    with pytest.raises(volreel.InputError, match="holds '000000.f32' and is not a volreel container"):
        volreel.encode(bad[:2], data, codec="zfp")
    assert sorted(p.name for p in data.iterdir()) == ["000000.f32"]


def test_encode_from_a_generator(series, tmp_path):
    _, _, frames = series
    out = tmp_path / "gen.vreel"

    def generate():
        for f in frames:
            yield f.astype(np.float64)  # converted as they come

    summary = volreel.encode(generate(), out, psnr=45, times=[0.5 * t for t in range(6)])
    assert summary["frames"] == 6 and summary["psnr"] >= 45 - 0.05
    c = volreel.open(out)
    assert c.frames == 6 and c.times == pytest.approx([0.5 * t for t in range(6)])
    assert sequence_psnr(frames, np.stack(list(c))) >= 45 - 0.05
    # The frames went through a temporary raw series beside `out`, removed after.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gen.vreel"]
    # Frames of different shapes: an error, and nothing left behind.
    mixed = [frames[0], frames[1][:, :, :20]]
    with pytest.raises(ValueError, match=r"frames\[1\].*differs"):
        volreel.encode(iter(mixed), tmp_path / "mixed.vreel")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gen.vreel"]
    # A name ending in a separator names the same folder; the temporary series goes beside it.
    volreel.encode(iter(frames[:2]), str(tmp_path / "slash.vreel") + "/", dictionary="dct")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gen.vreel", "slash.vreel"]
    # A generator's container resumes from a generator (the temporary series' name, which differs
    # from run to run, is not one of its settings).
    again = volreel.encode(iter(frames[:2]), tmp_path / "slash.vreel", dictionary="dct", resume=True)
    assert again["frames"] == 2


def test_encode_from_an_array_is_the_command_line_encode(series, tmp_path):
    path, _, frames = series
    run("encode", path, "--out", tmp_path / "cli.vreel", "--dictionary", "dct", "--psnr", "40")
    summary = volreel.encode(frames, tmp_path / "py.vreel", dictionary="dct", psnr=40)
    cli, py = volreel.open(tmp_path / "cli.vreel"), volreel.open(tmp_path / "py.vreel")
    assert py.info()["total_bytes"] == summary["bytes"]
    # The same frames (the manifests differ in the source they name).
    frame_bytes = [sum(f["bytes"] for f in c.info()["frames"]) for c in (cli, py)]
    assert frame_bytes[0] == frame_bytes[1]
    for t in range(6):
        assert np.array_equal(py[t], cli[t])
    # An existing container is kept unless asked.
    # The library's messages name the keywords, not the command line's options.
    with pytest.raises(volreel.InputError,
                       match="give resume=True to continue it or overwrite=True to replace it"):
        volreel.encode(frames, tmp_path / "py.vreel", dictionary="dct", psnr=40)
    with pytest.raises(volreel.InputError, match="brick_size must be auto or a multiple of 6") as e:
        volreel.encode(frames, tmp_path / "b.vreel", dictionary="dct", brick_size=7)
    assert "--" not in str(e.value)
    # A setting that differs is named with the keywords that set it.
    with pytest.raises(volreel.InputError, match=r"encoded with other settings") as e:
        volreel.encode(frames, tmp_path / "cli.vreel", dictionary="dct", psnr=45, resume=True)
    assert "set by tolerance, psnr, bps or max_error)" in str(e.value)
    assert "--" not in str(e.value)
    volreel.encode(frames, tmp_path / "py.vreel", codec="zfp", overwrite=True)
    assert volreel.open(tmp_path / "py.vreel").info()["codec"] == "zfp"


def test_a_missed_target_warns_and_says_so(series, tmp_path):
    _, _, frames = series
    met = volreel.encode(frames[:2], tmp_path / "met.vreel", dictionary="dct", psnr=40)
    assert met["targets_met"] is True
    # Past what the payload's finest steps hold: a warning with what was reached, and the
    # container is kept (complete and valid).
    with pytest.warns(RuntimeWarning, match=r"target PSNR 400\.00 dB missed: frame \d+ reached"):
        missed = volreel.encode(frames[:2], tmp_path / "missed.vreel", dictionary="dct", psnr=400)
    assert missed["targets_met"] is False and missed["psnr"] < 400
    assert volreel.open(tmp_path / "missed.vreel").frames == 2


def test_train_then_encode_with_the_dictionary(series, tmp_path):
    _, _, frames = series
    result = volreel.train(frames, tmp_path / "d.bin", atoms=32, psnr=45)
    assert result["atoms"] == 32 and (tmp_path / "d.bin").stat().st_size > 0
    # An existing file is kept unless asked, as by `volreel train`.
    before = (tmp_path / "d.bin").read_bytes()
    with pytest.raises(volreel.InputError, match="already exists: pass overwrite=True"):
        volreel.train(frames, tmp_path / "d.bin", atoms=16)
    assert (tmp_path / "d.bin").read_bytes() == before
    assert volreel.train(frames, tmp_path / "d.bin", atoms=16, overwrite=True)["atoms"] == 16
    with pytest.warns(RuntimeWarning, match=r"K = 4096 atoms from \d+ distinct training blocks.*"
                                            r"train fewer \(e.g. atoms=\d+\)"):
        volreel.train(frames[:1, :12, :12, :12], tmp_path / "many.bin", atoms=4096)
    volreel.train(frames, tmp_path / "d.bin", atoms=32, psnr=45, overwrite=True)
    with pytest.raises(volreel.InputError, match="is a directory"):
        volreel.train(frames, tmp_path, atoms=16)
    with pytest.raises(ValueError, match="psnr must be a finite number > 0"):
        volreel.train(frames, tmp_path / "p.bin", atoms=16, psnr=0)
    # Folders that do not exist yet are made, as encode makes them for a container.
    volreel.train(frames, tmp_path / "new" / "sub" / "d.bin", atoms=16)
    assert (tmp_path / "new" / "sub" / "d.bin").stat().st_size > 0
    s = volreel.encode(frames, tmp_path / "t.vreel", dictionary=str(tmp_path / "d.bin"), psnr=45)
    assert s["psnr"] >= 45 - 0.05


def test_ctrl_c_stops_an_encode_which_resume_completes(tmp_path):
    # Many small frames; once the first is written, a Ctrl-C (as the terminal sends it) arrives
    # while the encode runs without the GIL. It raises KeyboardInterrupt in the caller at the next
    # frame, not after the last; resume=True then completes the same container.
    frames = np.random.default_rng(5).standard_normal((400, 16, 16, 16)).astype(np.float32)
    out = tmp_path / "stopped.vreel"
    first = out / "frames" / "000000.vrf"

    def interrupt_once_started():
        while not first.exists():
            time.sleep(0.001)
        _thread.interrupt_main()

    watcher = threading.Thread(target=interrupt_once_started, daemon=True)
    watcher.start()
    with pytest.raises(KeyboardInterrupt):
        volreel.encode(frames, out, dictionary="dct", psnr=40)
    watcher.join()
    written = len(list((out / "frames").glob("*.vrf")))
    assert 1 <= written < 400
    summary = volreel.encode(frames, out, dictionary="dct", psnr=40, resume=True)
    assert summary["frames"] == 400 and volreel.open(out).frames == 400


def test_psnr_and_ssim_are_those_of_volreel_compare(series, tmp_path):
    _, meta, frames = series
    a, b = frames[0], frames[3]
    a.tofile(tmp_path / "a.f32")
    b.tofile(tmp_path / "b.f32")
    dims = "x".join(map(str, meta["dims"]))
    report = json.loads(run("compare", tmp_path / "a.f32", tmp_path / "b.f32", "--dims", dims,
                            "--json"))
    assert volreel.psnr(a, b) == pytest.approx(report["sequence"]["psnr"], rel=1e-12)
    assert volreel.ssim(a, b) == pytest.approx(report["frames"][0]["ssim"], rel=1e-9)
    assert volreel.psnr(a, a) == float("inf")
    assert volreel.ssim(a, a) == pytest.approx(1.0)
    # Other types are measured as float32, as volreel reads data: silently where that holds their
    # values, with a warning where it rounds them (differences of 1e-6 on values near 1000 were
    # measured as 102 dB where they are 120 dB).
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert volreel.psnr(a.astype(np.float64), b.astype(np.float64)) == volreel.psnr(a, b)
    fine = 1000 + np.random.default_rng(2).random((12, 12, 12))
    with pytest.warns(RuntimeWarning, match="psnr: a's float64 values rounded to float32"):
        volreel.psnr(fine, fine + 1e-6)


def test_the_notebook_style_example_runs(tmp_path):
    example = Path(__file__).resolve().parents[2] / "docs" / "python_example.py"
    env = dict(os.environ, MPLBACKEND="Agg")
    result = subprocess.run([os.sys.executable, example, tmp_path], check=True, env=env,
                            capture_output=True, text=True)
    assert "PSNR" in result.stdout, result.stdout
    psnr = float(result.stdout.split("time step 4: PSNR ")[1].split(" dB")[0])
    assert psnr >= 49.5
    assert (tmp_path / "slice.png").stat().st_size > 10000


def free_port():
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_container_on_a_web_server_reads_as_the_folder(container, tmp_path):
    """volreel.open(URL): nginx on 127.0.0.1 serving the container's folder."""
    import socket
    import time

    nginx = next(p for p in ("/usr/sbin/nginx", "/usr/local/sbin/nginx", "/usr/bin/nginx")
                 if os.path.exists(p))
    port = free_port()
    (tmp_path / "tmp").mkdir()
    conf = tmp_path / "nginx.conf"
    user = "user root;\n" if os.geteuid() == 0 else ""
    conf.write_text(
        f"{user}worker_processes 1;\nmaster_process off;\ndaemon off;\npid {tmp_path}/nginx.pid;\n"
        f"error_log {tmp_path}/error.log warn;\nevents {{ worker_connections 64; }}\n"
        f"http {{\n access_log off;\n client_body_temp_path {tmp_path}/tmp;\n"
        f" proxy_temp_path {tmp_path}/tmp;\n fastcgi_temp_path {tmp_path}/tmp;\n"
        f" uwsgi_temp_path {tmp_path}/tmp;\n scgi_temp_path {tmp_path}/tmp;\n"
        f" server {{ listen 127.0.0.1:{port}; root {container.parent}; }}\n}}\n")
    import ctypes
    import signal
    prctl = ctypes.CDLL(None).prctl  # looked up here: the child only calls it
    parent = os.getpid()

    def end_with_this_process():  # a crash of the test leaves no server holding its output
        prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the test ended before prctl
            os._exit(1)

    server = subprocess.Popen([nginx, "-p", str(tmp_path), "-e", str(tmp_path / "error.log"),
                               "-c", str(conf)], stdout=subprocess.DEVNULL,
                              stderr=subprocess.DEVNULL, preexec_fn=end_with_this_process)
    try:
        for _ in range(500):
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.01)
        remote = volreel.open(f"http://127.0.0.1:{port}/{container.name}")
        local = volreel.open(container)
        assert remote.frames == local.frames and remote.dims == local.dims
        for t in (0, 4):
            assert np.array_equal(remote.frame(t), local.frame(t))
        with pytest.raises(volreel.FormatError, match="404"):
            volreel.open(f"http://127.0.0.1:{port}/missing.vreel")
        # A network failure is also a ConnectionError, as Python's own are.
        with pytest.raises(ConnectionError, match="404"):
            volreel.open(f"http://127.0.0.1:{port}/missing.vreel")
        with pytest.raises(volreel.NetworkError, match="missing.vreel/manifest.json"):
            volreel.open(f"http://127.0.0.1:{port}/missing.vreel")
    finally:
        server.terminate()
        server.wait(timeout=10)


class SilentServer:
    """A server on 127.0.0.1 that accepts connections and never answers: a stalled request."""

    def __init__(self):
        import socket

        self.socket = socket.socket()
        self.socket.bind(("127.0.0.1", 0))
        self.socket.listen(16)
        self.port = self.socket.getsockname()[1]
        self.held = []
        self.thread = threading.Thread(target=self._accept, daemon=True)
        self.thread.start()

    def _accept(self):
        while True:
            try:
                connection, _ = self.socket.accept()
            except OSError:
                return
            self.held.append(connection)

    def close(self):
        import socket

        self.socket.shutdown(socket.SHUT_RDWR)
        self.socket.close()
        for c in self.held:
            c.close()


def test_open_takes_the_url_options_and_checks_them(container):
    url = "http://127.0.0.1:9/x.vreel"
    with pytest.raises(volreel.InputError, match="tries: expected 1..20"):
        volreel.open(url, tries=0)
    with pytest.raises(volreel.InputError, match="stall_timeout: expected 1..3600 seconds"):
        volreel.open(url, stall_timeout=0.5)
    with pytest.raises(volreel.InputError, match="connections: expected 1..64"):
        volreel.open(url, connections=65)
    with pytest.raises(volreel.InputError, match="ca_file: '/nonexistent.pem' is not a file"):
        volreel.open(url, ca_file="/nonexistent.pem")
    with pytest.raises(volreel.InputError, match="cache_size"):
        volreel.open(url, cache="/tmp", cache_size="lots")
    # A folder takes the keywords too (they apply to URLs only).
    assert volreel.open(container, tries=1, stall_timeout=2).frames == volreel.open(container).frames


def test_a_stalled_server_is_given_up_after_stall_timeout_and_tries():
    server = SilentServer()
    try:
        url = f"http://127.0.0.1:{server.port}/run.vreel"
        start = time.monotonic()
        with pytest.raises(volreel.NetworkError, match="manifest.json"):
            volreel.open(url, tries=1, stall_timeout=1)
        one = time.monotonic() - start
        start = time.monotonic()
        with pytest.raises(volreel.NetworkError, match="the last of 2 tries"):
            volreel.open(url, tries=2, stall_timeout=1)
        two = time.monotonic() - start
        # The default, 20 s and 4 tries, would take over a minute.
        assert one < 5 and two < 8, (one, two)
        assert two > one
    finally:
        server.close()


def test_ctrl_c_ends_a_wait_for_the_server():
    """A signal handler's exception (KeyboardInterrupt on Ctrl-C) comes out of volreel.open while it
    waits for a server that does not answer, not after the stall timeout."""
    import signal

    class Interrupted(Exception):
        pass

    def handler(signum, frame):
        raise Interrupted()

    server = SilentServer()
    previous = signal.signal(signal.SIGINT, handler)
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    try:
        start = time.monotonic()
        timer.start()
        with pytest.raises(Interrupted):
            volreel.open(f"http://127.0.0.1:{server.port}/run.vreel", stall_timeout=30)
        assert time.monotonic() - start < 5
    finally:
        timer.cancel()
        signal.signal(signal.SIGINT, previous)
        server.close()

"""A private PulseAudio daemon for tests and benchmarks: a real sound device path (PortAudio,
ALSA's pulse plugin, a sound server) that touches nothing of the machine's own.

    with PulseAudio() as pulse:
        os.environ.update(pulse.env)  # before PortAudio starts, or then audio_io.rescan_devices()
        source = open_source("mic")   # the null sink's monitor: what is played into it
        pulse.play(wav)

Measured on Debian 12 (PulseAudio 16.1, PortAudio 19.6, alsa-plugins 1.2.7), as root:

- ``pulseaudio --daemonize=no -n --exit-idle-time=-1`` runs as root without ``--system``
  (it only warns), given a runtime directory (XDG_RUNTIME_DIR, PULSE_RUNTIME_PATH) and a HOME
  of its own, where it keeps its state and cookie. ``-n`` loads no default script, so only
  the modules named here exist: the native protocol on a socket of ours (anonymous, so
  clients need no cookie) and a null sink, whose monitor is then the default source.
- ``--realtime=no --high-priority=no``: as root it otherwise takes nice -11 and SCHED_RR,
  on a machine that others share.
- Clients find it by ``PULSE_SERVER=unix:<socket>``. Debian's PortAudio has no PulseAudio
  host API: it gets there through ALSA's ``pulse`` plugin (libasound2-plugins).
  ``ALSA_CONFIG_PATH`` names the system's alsa.conf and then a file of ours that makes
  ALSA's ``default`` that plugin. The system's own hook (/etc/alsa/conf.d/99-pulse.conf)
  does the same only when a server answered as ALSA read its configuration, which is not so
  while the daemon restarts; a ~/.asoundrc would mean a HOME of our own for the whole test
  process, and /etc/asound.conf is the machine's.
- A null sink renders in 2 s blocks while no client asks for less, so the first capture
  from its monitor came 2 s late. A keeper, ``parec`` at 20 ms into /dev/null for the
  daemon's life, holds the sink at 20 ms: the first audio then comes within about 30 ms.
"""

from __future__ import annotations

import contextlib
import os
import select
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType

SYSTEM_ALSA = "/usr/share/alsa/alsa.conf"
ALSA_DEFAULT = "pcm.!default { type pulse }\nctl.!default { type pulse }\n"
TOOLS = ("pulseaudio", "pactl", "paplay", "parec")


def unavailable() -> str | None:
    """Why no private PulseAudio can run here (a Debian package missing), or None."""
    missing = [tool for tool in TOOLS if shutil.which(tool) is None]
    if missing:
        return f"{', '.join(missing)} not installed (apt-get install pulseaudio pulseaudio-utils)"
    return None


class PulseAudio:
    """The daemon, with a null sink `SINK`; a context manager that always stops it."""

    SINK = "voicectl"
    MONITOR = f"{SINK}.monitor"

    def __init__(self) -> None:
        # A directory of its own under /tmp: a unix socket's path must stay under 108 bytes,
        # which a pytest tmp_path with a long test name does not.
        self._directory = Path(tempfile.mkdtemp(prefix="voicectl-pulse-"))
        self.socket = self._directory / "run" / "native"
        self.server = f"unix:{self.socket}"
        self._alsa = self._directory / "asound.conf"
        self._log = self._directory / "pulseaudio.log"
        self._daemon: subprocess.Popen[bytes] | None = None
        self._keeper: subprocess.Popen[bytes] | None = None

    @property
    def env(self) -> dict[str, str]:
        """What a client process needs in its environment to use this daemon."""
        return {"PULSE_SERVER": self.server, "ALSA_CONFIG_PATH": f"{SYSTEM_ALSA}:{self._alsa}"}

    def __enter__(self) -> PulseAudio:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()

    def start(self, timeout: float = 15.0) -> None:
        """Start the daemon (again, after `stop`) and wait until its monitor delivers audio."""
        self._alsa.write_text(ALSA_DEFAULT)
        (self._directory / "run").mkdir(mode=0o700, exist_ok=True)
        (self._directory / "home").mkdir(exist_ok=True)
        with self._log.open("ab") as log:
            self._daemon = subprocess.Popen(
                [
                    "pulseaudio",
                    "--daemonize=no",
                    "-n",
                    "--exit-idle-time=-1",
                    "--realtime=no",
                    "--high-priority=no",
                    "--use-pid-file=no",
                    "--disallow-exit",
                    f"--load=module-native-protocol-unix socket={self.socket} auth-anonymous=1",
                    f"--load=module-null-sink sink_name={self.SINK}",
                ],
                stdout=log,
                stderr=subprocess.STDOUT,
                env=self._daemon_env(),
                start_new_session=True,
            )
        deadline = time.monotonic() + timeout
        self._until(lambda: self.pactl_ok("info"), deadline, "the daemon to answer")
        self._keeper = self._tool("parec", "--latency-msec=20", f"--device={self.MONITOR}")
        self._until(self._monitor_delivers, deadline, "its null sink's monitor to deliver")

    def stop(self) -> None:
        """Stop the daemon (its clients see their device go away)."""
        for process in (self._keeper, self._daemon):
            if process is not None and process.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGTERM)
                try:
                    process.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()
        self._keeper = self._daemon = None

    def close(self) -> None:
        """Stop the daemon and remove its directory."""
        self.stop()
        shutil.rmtree(self._directory, ignore_errors=True)

    def log(self) -> str:
        """What the daemon has said, for a failing test's report."""
        return self._log.read_text(errors="replace") if self._log.exists() else ""

    def pactl(self, *args: str) -> str:
        """`pactl ARGS` against this daemon; its output."""
        done = subprocess.run(
            ["pactl", *args], env=self._client_env(), capture_output=True, text=True, timeout=10
        )
        if done.returncode != 0:
            raise RuntimeError(f"pactl {' '.join(args)}: {done.stderr.strip()}")
        return done.stdout

    def pactl_ok(self, *args: str) -> bool:
        try:
            self.pactl(*args)
        except (RuntimeError, subprocess.TimeoutExpired):
            return False
        return True

    def play(self, wav: Path, timeout: float = 30.0) -> None:
        """Play a sound file into the null sink; return once it has been played."""
        subprocess.run(
            ["paplay", f"--device={self.SINK}", str(wav)],
            env=self._client_env(),
            check=True,
            timeout=timeout,
            capture_output=True,
        )

    @contextlib.contextmanager
    def recording(self) -> Iterator[Recording]:
        """What the null sink plays, as 16 kHz mono s16le, captured from its monitor."""
        process = self._tool(
            "parec",
            "--latency-msec=20",
            "--raw",
            "--format=s16le",
            "--rate=16000",
            "--channels=1",
            f"--device={self.MONITOR}",
            stdout=subprocess.PIPE,
        )
        recording = Recording(process)
        try:
            yield recording
        finally:
            recording.stop()

    def _tool(self, *command: str, stdout: int = subprocess.DEVNULL) -> subprocess.Popen[bytes]:
        return subprocess.Popen(
            command,
            stdout=stdout,
            stderr=subprocess.DEVNULL,
            env=self._client_env(),
            start_new_session=True,
        )

    def _monitor_delivers(self) -> bool:
        """Whether a fresh capture from the monitor gets audio within half a second."""
        probe = self._tool("parec", "--raw", f"--device={self.MONITOR}", stdout=subprocess.PIPE)
        try:
            assert probe.stdout is not None
            ready, _, _ = select.select([probe.stdout], [], [], 0.5)
            return bool(ready) and bool(os.read(probe.stdout.fileno(), 1))
        finally:
            probe.kill()
            probe.wait()
            if probe.stdout is not None:
                probe.stdout.close()

    def _until(self, condition: Callable[[], bool], deadline: float, what: str) -> None:
        while not condition():
            if self._daemon is not None and self._daemon.poll() is not None:
                raise RuntimeError(f"pulseaudio exited ({self._daemon.returncode}):\n{self.log()}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"timed out waiting for {what}:\n{self.log()}")
            time.sleep(0.05)

    def _daemon_env(self) -> dict[str, str]:
        env = {k: v for k, v in os.environ.items() if not k.startswith("PULSE_")}
        runtime = self._directory / "run"
        return {
            **env,
            "HOME": str(self._directory / "home"),
            "XDG_RUNTIME_DIR": str(runtime),
            "XDG_CONFIG_HOME": str(self._directory / "home" / ".config"),
            "PULSE_RUNTIME_PATH": str(runtime / "pulse"),
        }

    def _client_env(self) -> dict[str, str]:
        return {**os.environ, **self.env}


class Recording:
    """A capture in progress: `pcm` is what it has heard so far."""

    def __init__(self, process: subprocess.Popen[bytes]) -> None:
        self._process = process
        self._chunks: list[bytes] = []
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()

    @property
    def pcm(self) -> bytes:
        with self._lock:
            return b"".join(self._chunks)

    def _drain(self) -> None:
        assert self._process.stdout is not None
        while chunk := os.read(self._process.stdout.fileno(), 65536):
            with self._lock:
                self._chunks.append(chunk)

    def stop(self) -> None:
        self._process.terminate()
        self._process.wait(timeout=5)
        self._reader.join(timeout=5)
        if self._process.stdout is not None:
            self._process.stdout.close()

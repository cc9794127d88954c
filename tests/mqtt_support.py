"""A real mosquitto broker on 127.0.0.1 for the tests, and a recording subscriber."""

from __future__ import annotations

import getpass
import json
import os
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

MOSQUITTO = shutil.which(
    "mosquitto", path=os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/usr/local/sbin"])
)

needs_mosquitto = pytest.mark.skipif(
    MOSQUITTO is None,
    reason="mosquitto is not installed (apt-get install mosquitto; .ci/run installs it)",
)


#: brokers started and not stopped yet: `stop_brokers` ends them after every test, also a
#: failed one (a broker left running outlives the test run)
RUNNING: set[Broker] = set()


@pytest.fixture(autouse=True)
def stop_brokers():
    yield
    for broker in list(RUNNING):
        broker.stop()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class Broker:
    """mosquitto with a generated config, persistence in ``folder``; start/stop/restart."""

    def __init__(self, folder: Path, port: int | None = None, extra: str = "") -> None:
        self.folder = folder
        self.folder.mkdir(parents=True, exist_ok=True)
        self.port = port or free_port()
        self.config = folder / "mosquitto.conf"
        self.log = folder / "mosquitto.log"
        self.config.write_text(
            f"user {getpass.getuser()}\n"  # as root, mosquitto would switch to "mosquitto"
            f"listener {self.port} 127.0.0.1\n"
            f"persistence true\npersistence_location {folder}/\n"
            f"log_dest file {self.log}\nlog_type all\n"
            + extra
            + ("" if "allow_anonymous" in extra else "allow_anonymous true\n")
        )
        self.proc: subprocess.Popen | None = None

    def start(self, timeout_s: float = 20.0) -> Broker:
        self.proc = subprocess.Popen(
            [MOSQUITTO, "-c", str(self.config)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        RUNNING.add(self)
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise RuntimeError(
                    f"mosquitto exited: {self.proc.stderr.read().decode()}{self.tail()}"
                )
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.5).close()
                return self
            except OSError:
                time.sleep(0.05)
        raise RuntimeError(f"mosquitto did not listen on {self.port}{self.tail()}")

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.proc = None
        RUNNING.discard(self)

    def tail(self) -> str:
        text = self.log.read_text(errors="replace") if self.log.exists() else ""
        return "\n--- mosquitto log\n" + "\n".join(text.splitlines()[-30:])


#: how long a `Subscriber` waits for the broker to confirm its subscription
SUBSCRIBE_TIMEOUT_S = 30.0


class Subscriber:
    """A paho client that records every message of ``topic`` (persistent session, QoS 1)."""

    def __init__(
        self, port: int, topic: str, client_id: str = "fdi-test-subscriber", **connect
    ) -> None:
        import paho.mqtt.client as mqtt

        self.messages: list[dict] = []  # {"topic", "payload", "retain", "dup", "qos"}
        self._lock = threading.Lock()
        self.topic = topic
        self.client = mqtt.Client(
            mqtt.CallbackAPIVersion.VERSION2, client_id=client_id, clean_session=False
        )
        if "username" in connect:
            self.client.username_pw_set(connect["username"], connect.get("password"))
        if "ca_file" in connect:
            self.client.tls_set(ca_certs=connect["ca_file"])
        subscribed = threading.Event()
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(topic, qos=1)
        self.client.on_subscribe = lambda c, u, mid, codes, p: subscribed.set()
        self.client.on_message = self._on_message
        self.client.reconnect_delay_set(0.2, 1.0)
        self.client.connect_async("127.0.0.1", port, 30)
        self.client.loop_start()
        # listening once made: a message published before the broker's SUBACK would not
        # reach this session (it had no subscription yet)
        if not subscribed.wait(SUBSCRIBE_TIMEOUT_S):
            self.close()
            raise AssertionError(
                f"the subscriber to {topic} got no SUBACK within {SUBSCRIBE_TIMEOUT_S:g} s"
            )

    def _on_message(self, client, userdata, msg) -> None:
        with self._lock:
            self.messages.append(
                {
                    "topic": msg.topic,
                    "payload": json.loads(msg.payload),
                    "retain": bool(msg.retain),
                    "dup": bool(msg.dup),
                    "qos": msg.qos,
                }
            )

    def on(self, suffix: str) -> list[dict]:
        with self._lock:
            return [m for m in self.messages if m["topic"].endswith(suffix)]

    def events(self) -> list[dict]:
        """The messages on the event sub-topics ``.../event/<kind>``."""
        with self._lock:
            return [m for m in self.messages if m["topic"].rpartition("/")[0].endswith("/event")]

    def wait(self, predicate, timeout_s: float, what: str, explain=lambda: ""):
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            value = predicate(self)
            if value:
                return value
            time.sleep(0.1)
        raise AssertionError(
            f"timed out waiting for {what}; got "
            f"{[m['topic'] for m in self.messages][-20:]}{explain()}"
        )

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()

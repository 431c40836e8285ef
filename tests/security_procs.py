"""Raw Zenoh processes for tests/test_security.py: a watcher that reports everything of a fleet it is let see,
and a forger that publishes under another vehicle's key. Run as ``python -m tests.security_procs``.

Both open their session from a Zenoh configuration file the way the agents do
(:func:`agents.transport.session.make_config`), print JSON lines, and stay until their stdin closes.

- ``watch CONFIG FLEET``: subscribes to ``evopose/<fleet>/**`` and to the fleet's liveliness tokens (with
  history); prints ``ready``, then ``sample`` (key) and ``token`` (key, put/delete) events.
- ``forge CONFIG FLEET VICTIM OWN COUNT``: declares the liveliness tokens of VICTIM then OWN, then puts
  COUNT times a hint under VICTIM's key followed by one under OWN's key (one session, one priority: in
  order), and prints ``done``. A receiver that has OWN's last hint would already have every forged one the
  router let through.
"""

from __future__ import annotations

import json
import sys
import threading
from pathlib import Path

import zenoh

from agents.transport.session import SessionOptions, make_config


def say(record: dict) -> None:
    sys.stdout.write(json.dumps(record) + "\n")
    sys.stdout.flush()


def open_from(config: str) -> zenoh.Session:
    return zenoh.open(make_config(SessionOptions(config_file=Path(config))))


def watch(config: str, fleet: str) -> None:
    lock = threading.Lock()

    def on_sample(sample: zenoh.Sample) -> None:
        with lock:
            say({"event": "sample", "key": str(sample.key_expr)})

    def on_token(sample: zenoh.Sample) -> None:
        with lock:
            say({"event": "token", "key": str(sample.key_expr),
                 "kind": "put" if sample.kind == zenoh.SampleKind.PUT else "delete"})

    with open_from(config) as session:
        data = session.declare_subscriber(f"evopose/{fleet}/**", on_sample)
        tokens = session.liveliness().declare_subscriber(f"evopose/{fleet}/@alive/*", on_token, history=True)
        with lock:
            say({"event": "ready"})
        sys.stdin.read()  # until the test closes stdin
        data.undeclare()
        tokens.undeclare()


def forge(config: str, fleet: str, victim: str, own: str, count: int) -> None:
    with open_from(config) as session:
        liveliness = session.liveliness()
        forged_token = liveliness.declare_token(f"evopose/{fleet}/@alive/{victim}")
        own_token = liveliness.declare_token(f"evopose/{fleet}/@alive/{own}")
        payload = bytes(24)
        for _ in range(count):
            session.put(f"evopose/{fleet}/{victim}/hint", payload, congestion_control=zenoh.CongestionControl.BLOCK)
            session.put(f"evopose/{fleet}/{own}/hint", payload, congestion_control=zenoh.CongestionControl.BLOCK)
        say({"event": "done", "sent": count})
        sys.stdin.read()
        forged_token.undeclare()
        own_token.undeclare()


if __name__ == "__main__":
    command, *args = sys.argv[1:]
    if command == "watch":
        watch(*args)
    elif command == "forge":
        forge(args[0], args[1], args[2], args[3], int(args[4]))
    else:
        raise SystemExit(f"unknown command {command!r}")

"""What the transport refused, counted where the peer can see it (secure mode).

Zenoh reports an access-control refusal only as a trace line of its access-control module; a
secure peer's transport (``peers.transport``) runs a :class:`RefusalLog` that reads those lines
off the process's standard output and counts them.
"""

from __future__ import annotations

import os
import re
import sys
import threading

import zenoh

ACL_LOG = "zenoh::net::routing::interceptor::access_control=trace"
"""Zenoh reports each refusal only as a trace line of its access-control module (the
publisher gets no error): a secure peer turns that module's trace on and counts the lines."""
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_CHECK = re.compile(r"(ThreadId\(\d+\)).*?access_control: (Using cached result: )?"
                    r"([0-9a-f]+)( on \S*?CertCommonName\(([^)]*)\))?.*? is (un)?authorized to "
                    r"(.+?) \((ingress|egress)\) on (\S+)")
_CACHE_GROUP = 9
"""Zenoh logs one line per message type (9) after "caching permissions for": not messages."""
_log_started = False


class RefusalLog:
    """Counts the access-control refusals of this process's Zenoh session.

    Zenoh writes its log to file descriptor 1; while running, this points descriptor 1 at a
    pipe, counts the refusal lines, and passes every other line on to the real stdout (the
    process's own prints go the same way, in order). ``counts()``: ``{"<sender> <message>
    <key>": n}`` for what arrived here and was refused (ingress).
    """

    def __init__(self) -> None:
        self._counts: dict[str, int] = {}
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._saved: int | None = None

    def start(self) -> RefusalLog:
        global _log_started

        sys.stdout.flush()
        r, w = os.pipe()
        self._saved = os.dup(1)
        os.dup2(w, 1)
        os.close(w)
        self._thread = threading.Thread(target=self._read, args=(r,), daemon=True,
                                        name="acl-log")
        self._thread.start()
        if not _log_started:
            zenoh.init_log_from_env_or(f"warn,{ACL_LOG}")
            _log_started = True
        return self

    def _read(self, r: int) -> None:
        skip: dict[str, int] = {}
        names: dict[str, str] = {}  # Zenoh id -> certificate common name
        out = self._saved
        with os.fdopen(r, "rb", buffering=0) as pipe:
            buf = b""
            while True:
                chunk = pipe.read(65536)
                if not chunk:
                    break
                buf += chunk
                *lines, buf = buf.split(b"\n")
                passed = []
                for raw in lines:
                    if b"interceptor::access_control" not in raw:
                        passed.append(raw)
                        continue
                    line = _ANSI.sub("", raw.decode("utf-8", "replace"))
                    if "caching permissions" in line:
                        m = re.search(r"(ThreadId\(\d+\))", line)
                        if m:
                            skip[m.group(1)] = _CACHE_GROUP
                        continue
                    m = _CHECK.search(line)
                    if m is None:
                        continue
                    thread, cached, zid, _, cn, un, what, flow, key = m.groups()
                    if cn:
                        names[zid] = cn
                    if not cached and skip.get(thread, 0) > 0:  # a cache entry, no message
                        skip[thread] -= 1
                        continue
                    if un and flow == "ingress":
                        who = names.get(zid, zid[:8])
                        label = f"{who} {what.replace('Declare/Undeclare ', '')} {key}"
                        with self._lock:
                            self._counts[label] = self._counts.get(label, 0) + 1
                if passed:
                    os.write(out, b"".join(p + b"\n" for p in passed))
            if buf:
                os.write(out, buf)

    def counts(self) -> dict[str, int]:
        with self._lock:
            return dict(self._counts)

    def total(self) -> int:
        with self._lock:
            return sum(self._counts.values())

    def stop(self) -> None:
        """Point descriptor 1 back at the real stdout and pass on what is left."""
        if self._saved is None:
            return
        try:
            sys.stdout.flush()
        except Exception:
            pass
        os.dup2(self._saved, 1)  # closes the pipe's last write end: the reader drains, ends
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        os.close(self._saved)
        self._saved = None

"""``sray ui``: the MLflow dashboard of a local store until Ctrl-C, SIGTERM or SIGHUP; of a server, its runs views."""

from __future__ import annotations

import argparse
import signal
import sys
from typing import Any

from sray.jobs.methods.flags import refuse
from sray.platform.tracking.dashboard import DEFAULT_UI_PORT, is_server, server_links, start_dashboard, tunnel_hint


class _Stop(Exception):
    """Raised in the main thread by SIGTERM or SIGHUP: stop the dashboard and exit."""


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray ui``."""
    p = sub.add_parser("ui", help="open the MLflow dashboard (runs, fleets, charts, renders) on 127.0.0.1")
    p.add_argument("--tracking-uri", help="store to show (default: the SQLite store in this folder, mlflow.db), or "
                                          "a tracking server (http://...), whose own dashboard is listed")
    p.add_argument("--port", type=int, default=DEFAULT_UI_PORT, help=f"port (default {DEFAULT_UI_PORT})")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; reach it from elsewhere through an SSH tunnel)")
    p.set_defaults(func=run)


def _show_server(uri: str) -> int:
    """List a tracking server's experiments and their runs views; exit 2 when it does not answer."""
    try:
        links = server_links(uri)
    except ConnectionError as e:
        return refuse("ui", e)
    print(f"[sray] {uri} is a tracking server: its dashboard is {uri.rstrip('/')}/")
    for name, url in links.items():
        print(f"[sray]   runs of experiment {name!r}: {url}")
    return 0


def _raise_stop(signum: int, frame: Any) -> None:
    raise _Stop(signal.Signals(signum).name)


def run(args: argparse.Namespace) -> int:
    """Start the dashboard, print where to open it, serve until stopped; exit 1 if the server dies."""
    if args.tracking_uri and is_server(args.tracking_uri):
        return _show_server(args.tracking_uri)
    previous = {sig: signal.signal(sig, _raise_stop) for sig in (signal.SIGTERM, signal.SIGHUP)}
    handle = None
    try:
        print(f"[sray] starting the MLflow dashboard on {args.host}:{args.port} ...", flush=True)
        try:
            handle = start_dashboard(args.tracking_uri, port=args.port, host=args.host)
        except (ValueError, OSError, RuntimeError) as e:  # no store, port taken, server failed
            return refuse("ui", e)
        print(f"[sray] MLflow dashboard: {handle.url}")
        for name, url in handle.experiment_urls.items():
            print(f"[sray]   runs of experiment {name!r}: {url}")
        print(f"[sray] {tunnel_hint(args.port)}")
        print(f"[sray] server log: {handle.log_path}; Ctrl-C stops the dashboard", flush=True)
        code = handle.process.wait()
    except (KeyboardInterrupt, _Stop) as e:  # whenever it comes; start_dashboard stops a server still starting
        print(f"\n[sray] stopping the dashboard ({e or 'Ctrl-C'})", flush=True)
        return 0
    finally:
        if handle is not None:
            handle.stop()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    print(f"sray ui: the MLflow server exited with code {code}; its log ends with:\n{handle.log_tail()}",
          file=sys.stderr)
    return 1

"""``sray ui``: the MLflow dashboard on a local store, until Ctrl-C."""

from __future__ import annotations

import argparse
import sys


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``sray ui``."""
    from sray.platform.tracking.dashboard import DEFAULT_UI_PORT

    p = sub.add_parser("ui", help="open the MLflow dashboard (runs, fleets, charts, renders) on 127.0.0.1")
    p.add_argument("--tracking-uri", help="store to show (default: the SQLite store in this folder, mlflow.db)")
    p.add_argument("--port", type=int, default=DEFAULT_UI_PORT, help=f"port (default {DEFAULT_UI_PORT})")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; reach it from elsewhere through an SSH tunnel)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Start the dashboard, print where to open it, serve until Ctrl-C; exit 1 if the server dies."""
    from sray.platform.tracking.dashboard import start_dashboard, tunnel_hint

    print(f"[sray] starting the MLflow dashboard on {args.host}:{args.port} ...", flush=True)
    try:
        handle = start_dashboard(args.tracking_uri, port=args.port, host=args.host)
    except (ValueError, OSError, RuntimeError) as e:  # no store, a server URI, port taken, server failed
        print(f"sray ui: {e}", file=sys.stderr)
        return 2
    print(f"[sray] MLflow dashboard: {handle.url}")
    for name, url in handle.experiment_urls.items():
        print(f"[sray]   runs of experiment {name!r}: {url}")
    print(f"[sray] {tunnel_hint(args.port)}")
    print(f"[sray] server log: {handle.log_path}; Ctrl-C stops the dashboard", flush=True)
    try:
        code = handle.process.wait()
    except KeyboardInterrupt:
        print("\n[sray] stopping the dashboard", flush=True)
        handle.stop()
        return 0
    print(f"sray ui: the MLflow server exited with code {code}; its log ends with:\n{handle.log_tail()}",
          file=sys.stderr)
    return 1

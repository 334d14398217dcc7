"""The far end of :class:`robofabric.lab.RemotePython`: runs snippets sent on stdin, each in its own thread.

Protocol: one JSON object per line on stdin, ``{"id": N, "code": "..."}``; for each, one line on
stdout, ``\\x1eLAB {"id": N, "ok": true, "value": ...}`` (the JSON of the snippet's last expression, as in a REPL) or
``{"id": N, "ok": false, "error": TRACEBACK}``. Snippets share one global namespace, so a ``World`` opened
by one is used by the next. Stdin closing ends the process. A test tool: it runs whatever it is sent.
"""

from __future__ import annotations

import ast
import json
import sys
import threading
import traceback

_OUT = threading.Lock()


def _plain(value):
    try:
        json.dumps(value)
        return value
    except TypeError:
        if hasattr(value, "tolist"):
            return value.tolist()
        if isinstance(value, (list, tuple)):
            return [_plain(v) for v in value]
        if isinstance(value, dict):
            return {str(k): _plain(v) for k, v in value.items()}
        return repr(value)


def _reply(obj: dict) -> None:
    line = "\x1eLAB " + json.dumps(obj)
    with _OUT:
        sys.stdout.write(line + "\n")
        sys.stdout.flush()


def _run(rid: int, code: str, ns: dict) -> None:
    try:
        tree = ast.parse(code, f"<lab snippet {rid}>")
        last = tree.body.pop() if tree.body and isinstance(tree.body[-1], ast.Expr) else None
        exec(compile(tree, f"<lab snippet {rid}>", "exec"), ns)
        value = (
            eval(compile(ast.Expression(last.value), f"<lab snippet {rid}>", "eval"), ns) if last is not None else None
        )
        _reply({"id": rid, "ok": True, "value": _plain(value)})
    except BaseException:
        _reply({"id": rid, "ok": False, "error": traceback.format_exc()})


def main() -> None:
    ns: dict = {"__name__": "__lab__"}
    for line in sys.stdin:
        if not line.strip():
            continue
        msg = json.loads(line)
        threading.Thread(target=_run, args=(msg["id"], msg["code"], ns), daemon=True).start()


if __name__ == "__main__":
    main()

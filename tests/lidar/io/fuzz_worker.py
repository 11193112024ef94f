"""Child process of the fuzz suite: reads damaged files under an address-space limit.

Reads one JSON request a line on stdin (``{"path": ..., "campaign": ...}``)
and answers one JSON line on stdout: ``{"outcome": "ok" | "refused" | "bug",
"message": ..., "unchanged": bool | null}``. The parent enforces the time
limit per case by killing this process.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import resource
import sys
import traceback
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path


def tree_digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.name == ".lock" or p.name.endswith(("-wal", "-shm", "-journal")):
            continue
        h.update(str(p.relative_to(folder)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def handle(req: dict) -> dict:
    from common.errors import ScanFormatError, SurveyError

    path = req["path"]
    if req.get("campaign"):
        from app.cli.main import main

        camp = Path(req["campaign"])
        before = tree_digest(camp)
        err = io.StringIO()
        try:
            with redirect_stderr(err), redirect_stdout(io.StringIO()):
                code = main(["add-epoch", str(camp), "--date", req.get("date", "2026-01-05T10:00"), "--coarse", path])
        except BaseException as exc:  # noqa: BLE001 - anything escaping main() is a bug
            return {"outcome": "bug", "message": f"{type(exc).__name__}: {exc}"[:300], "unchanged": None}
        lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
        unchanged = tree_digest(camp) == before
        if code == 0:
            return {"outcome": "ok", "message": "", "unchanged": unchanged}
        return {"outcome": "refused" if len(lines) == 1 and path in lines[0] else "bug",
                "message": " | ".join(lines)[:300], "unchanged": unchanged}
    from lidar.io import read_scans

    if req.get("info"):  # bridgesurvey info at header speed, or --stats
        from lidar.io.info import describe_file

        try:
            with redirect_stderr(io.StringIO()):
                describe_file(path, stats=req["info"] == "stats")
        except SurveyError as exc:
            msg = str(exc)
            return {"outcome": "refused" if "\n" not in msg and path in msg else "bug", "message": msg[:300]}
        except BaseException as exc:  # noqa: BLE001 - anything else is a bug
            return {"outcome": "bug", "message": f"{type(exc).__name__}: {exc}"[:300]}
        return {"outcome": "ok", "message": ""}
    try:
        scans = read_scans(path)
    except ScanFormatError as exc:
        msg = str(exc)
        ok = "\n" not in msg and path in msg
        return {"outcome": "refused" if ok else "bug", "message": msg[:300]}
    except SurveyError as exc:
        return {"outcome": "bug", "message": f"SurveyError but not ScanFormatError: {exc}"[:300]}
    except BaseException as exc:  # noqa: BLE001 - anything else is a bug
        return {"outcome": "bug", "message": f"{type(exc).__name__}: {exc}"[:200] + " " +
                traceback.format_exc().splitlines()[-3][:100]}
    import numpy as np

    if not scans or any(not np.isfinite(s.xyz_socs).all() or len(s) == 0 for s in scans):
        return {"outcome": "bug", "message": "read 'successfully' but with no or non-finite points"}
    return {"outcome": "ok", "message": f"{sum(len(s) for s in scans)} points"}


def main() -> None:
    limit = int(os.environ.get("FUZZ_AS_LIMIT", str(3 << 30)))
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    import app.cli.main  # noqa: F401
    import lidar.io  # noqa: F401  (import before answering "ready")

    sys.stdout.write(json.dumps({"ready": True}) + "\n")
    sys.stdout.flush()
    for line in sys.stdin:
        req = json.loads(line)
        res = handle(req)
        sys.stdout.write(json.dumps(res) + "\n")
        sys.stdout.flush()


if __name__ == "__main__":
    main()

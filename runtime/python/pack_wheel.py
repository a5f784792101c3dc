#!/usr/bin/env python3
"""Packs the `zoo` wheel from an extension library cargo has already built.

    python3 runtime/python/pack_wheel.py --lib target/debug/lib_native.so --out target/python-wheels

The release wheel is maturin's (`bash runtime/python/build.sh`). The test suite builds the extension in
its own profile and target dir, as part of the workspace's build (`cargo build --workspace
--lib`), and packs it with this script instead of compiling it a second time: the wheel holds
`zoo/` (the Python sources and stubs), the library as `zoo/_native.abi3.so`, and the
`.dist-info` that maturin writes for `runtime/python/pyproject.toml` (`maturin pep517 write-dist-info`:
name, version, `Requires-Dist`, tag), with its RECORD. Prints the wheel's path.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lib", required=True, type=Path, help="the built extension (lib_native.so)")
    ap.add_argument("--out", required=True, type=Path, help="folder for the wheel")
    ap.add_argument("--maturin", default=shutil.which("maturin") or "maturin", help="maturin executable")
    a = ap.parse_args()
    if not a.lib.is_file():
        print(f"error: {a.lib} does not exist: build it with `cargo build --workspace --lib`", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        r = subprocess.run(
            [a.maturin, "pep517", "write-dist-info", "-m", str(HERE / "Cargo.toml"), "--metadata-directory", tmp],
            capture_output=True,
            text=True,
        )
        if r.returncode != 0:
            print(f"error: maturin could not write the wheel's metadata:\n{r.stderr}", file=sys.stderr)
            return 2
        dist_info = next(Path(tmp).glob("*.dist-info"))
        wheel_meta = (dist_info / "WHEEL").read_text()
        tag = next(line.split(": ", 1)[1].strip() for line in wheel_meta.splitlines() if line.startswith("Tag: "))
        files: list[tuple[str, bytes]] = []
        package = HERE / "zoo"
        for p in sorted(package.iterdir()):
            if p.suffix in (".py", ".pyi") or p.name == "py.typed":
                files.append((f"zoo/{p.name}", p.read_bytes()))
        files.append(("zoo/_native.abi3.so", a.lib.read_bytes()))
        for p in sorted(dist_info.iterdir()):
            files.append((f"{dist_info.name}/{p.name}", p.read_bytes()))
        record_name = f"{dist_info.name}/RECORD"
        record = "\n".join([record_line(n, d) for n, d in files] + [f"{record_name},,", ""])
        files.append((record_name, record.encode()))
        name_version = dist_info.name[: -len(".dist-info")]
        a.out.mkdir(parents=True, exist_ok=True)
        wheel = a.out / f"{name_version}-{tag}.whl"
        tmp_wheel = wheel.with_suffix(".whl.tmp")
        with zipfile.ZipFile(tmp_wheel, "w", zipfile.ZIP_DEFLATED) as z:
            for n, d in files:
                info = zipfile.ZipInfo(n, date_time=(2026, 1, 1, 0, 0, 0))
                info.external_attr = (0o755 if n.endswith(".so") else 0o644) << 16
                info.compress_type = zipfile.ZIP_DEFLATED
                z.writestr(info, d)
        os.replace(tmp_wheel, wheel)
    print(wheel)
    return 0


if __name__ == "__main__":
    sys.exit(main())

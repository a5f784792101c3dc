#!/usr/bin/env python3
"""Makes the add-on zip with the `zoo` wheel inside: installable in Blender 3.4+ (Preferences >
Add-ons > Install) and, with its `blender_manifest.toml`, as a Blender 4.2+ extension (Blender
installs the wheel; older versions extract it on first use).

    python3 apps/blender/make_addon.py                      # builds the release wheel (runtime/python/build.sh)
    python3 apps/blender/make_addon.py --wheel target/wheels/zoo-0.1.0-cp39-abi3-manylinux_2_34_x86_64.whl

Writes target/zoo_blender.zip (or --out).
"""

import argparse
import glob
import os
import subprocess
import sys
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
ADDON = HERE / "zoo_blender"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--wheel", type=Path, help="the zoo wheel to bundle (default: build the release wheel)")
    ap.add_argument("--out", type=Path, default=REPO / "target" / "zoo_blender.zip")
    a = ap.parse_args()
    wheel = a.wheel
    if wheel is None:
        subprocess.run(["bash", str(REPO / "runtime" / "python" / "build.sh")], check=True)
        built = sorted(glob.glob(str(REPO / "target" / "wheels" / "zoo-*.whl")), key=os.path.getmtime)
        if not built:
            sys.exit("error: runtime/python/build.sh made no wheel in target/wheels")
        wheel = Path(built[-1])
    if not wheel.is_file():
        sys.exit(f"error: {wheel} does not exist")
    a.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = a.out.with_name(a.out.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for p in sorted(ADDON.rglob("*")):
            rel = p.relative_to(ADDON)
            if p.is_dir() or "__pycache__" in rel.parts or rel.parts[0] in ("_vendor", "wheels"):
                continue
            data = p.read_bytes()
            if rel.name == "blender_manifest.toml":
                data = data.replace(b"wheels = []", f'wheels = ["./wheels/{wheel.name}"]'.encode())
            z.writestr(f"zoo_blender/{rel.as_posix()}", data)
        z.write(wheel, f"zoo_blender/wheels/{wheel.name}")
    os.replace(tmp, a.out)
    print(a.out)


if __name__ == "__main__":
    main()

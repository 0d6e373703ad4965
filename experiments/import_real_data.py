"""Convert the shared real recordings into ``data/real/`` and register them.

    python experiments/import_real_data.py [--realdata ../shared/realdata]

Runs the importers (``pneubayes import gtdynamics`` on the five GTDynamics trials,
``pneubayes import respiraworks`` on the twelve ventilator runs), copies each data set's
licence file beside it, and lists every written file with its sha256 in
``data/registry.json`` (the bench entries are kept as they are). The inputs are never
modified; their own sha256 are in each sidecar's ``import`` key.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
from pathlib import Path

from pneubayes.atomic import write_json_atomic
from pneubayes.io.importers import import_gtdynamics, import_respiraworks

ROOT = Path(__file__).resolve().parents[1]
SETS = {
    "real/gtdynamics": {
        "what": "GTDynamics jumping robot (borglab/GTDynamics 2dd29bf3, BSD-2-Clause): four "
                "McKibben muscles per trial filled through on/off valves from a draining "
                "tank, 500 Hz raw psi gauge, trigger to 0.33 s; rig card "
                "gtdynamics-muscle.rig.json",
        "licence": "gtdynamics-jumping-robot/LICENSE_GTDynamics_BSD-2-Clause.txt",
        "regenerate": "pneubayes import gtdynamics ../shared/realdata/"
                      "gtdynamics-jumping-robot/trials/* --out data/real/gtdynamics",
    },
    "real/respiraworks": {
        "what": "RespiraWorks ventilator (RespiraWorks/Ventilator 718bce04, Apache-2.0): "
                "QuickLung test lung, AIR and OXY runs 1-6, 100 Hz, kPa gauge, closed loop; "
                "rig cards respiraworks-{air,oxy}.rig.json",
        "licence": "respiraworks-ventilator/LICENSE_RespiraWorks_Apache-2.0.txt",
        "regenerate": "pneubayes import respiraworks ../shared/realdata/"
                      "respiraworks-ventilator/{AIR,OXY}/*.dat --out data/real/respiraworks",
    },
}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--realdata", default=str(ROOT.parent / "shared" / "realdata"))
    args = ap.parse_args(argv)
    src = Path(args.realdata)
    data = ROOT / "data"
    gtd = sorted((src / "gtdynamics-jumping-robot" / "trials").iterdir())
    import_gtdynamics(gtd, data / "real" / "gtdynamics")
    rw = sorted((src / "respiraworks-ventilator").glob("[AO][IX][RY]/*.dat"))
    import_respiraworks(rw, data / "real" / "respiraworks")
    reg_path = data / "registry.json"
    reg = json.loads(reg_path.read_text())
    files = [e for e in reg["files"] if not e["file"].startswith("real/")]
    for name, info in SETS.items():
        lic = src / info["licence"]
        shutil.copyfile(lic, data / name / lic.name)
        for f in sorted((data / name).rglob("*")):
            if f.is_file():
                rel = f.relative_to(data).as_posix()
                files.append({"file": rel,
                              "sha256": hashlib.sha256(f.read_bytes()).hexdigest(),
                              "set": name, "what": info["what"],
                              "regenerate": info["regenerate"]})
    reg["files"] = files
    write_json_atomic(reg_path, reg)
    print(f"{reg_path}: {sum(1 for e in files if e['file'].startswith('real/'))} real files")
    return 0


if __name__ == "__main__":
    sys.exit(main())

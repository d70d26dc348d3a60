#!/usr/bin/env python3
"""Checks docker/compose.distributed.yaml without a Docker engine: the YAML parses, the services and
their dependencies are there, and every flag and BSPVT_* variable the API and worker
services use is one that `bspvt-server` accepts (from its --help).

    python3 docker/check.py [path/to/bspvt-server]
"""
import re
import subprocess
import sys
from pathlib import Path

import yaml

here = Path(__file__).resolve().parent
binary = sys.argv[1] if len(sys.argv) > 1 else str(here.parent / "target/debug/bspvt-server")
doc = yaml.safe_load((here / "compose.distributed.yaml").read_text())
services = doc["services"]
for name in ["postgres", "minio", "bucket", "api", "worker"]:
    assert name in services, f"service {name} missing"
for name, svc in services.items():
    for dep in (svc.get("depends_on") or {}):
        assert dep in services, f"{name} depends on unknown {dep}"
assert (here / "Dockerfile").exists()

for name in ["api", "worker"]:
    svc = services[name]
    cmd = svc["command"]
    help_text = subprocess.run([binary, cmd[0], "--help"], capture_output=True, text=True,
                               check=True).stdout
    for flag in [c for c in cmd[1:] if c.startswith("--")]:
        assert re.search(rf"\s{re.escape(flag)}\b", help_text), f"{name}: {flag} unknown"
    for var in [v for v in svc["environment"] if v.startswith("BSPVT_")]:
        assert re.search(rf"env: {var}[=\]]", help_text), f"{name}: {var} not read by `{cmd[0]}`"
    env = svc["environment"]
    assert env["BSPVT_DATABASE"].startswith("postgres://"), "database"
    assert env["BSPVT_STORE"].startswith("s3://"), "store"
    bucket = env["BSPVT_STORE"][len("s3://"):].split("/")[0]
    assert f"local/{bucket}" in " ".join(services["bucket"]["entrypoint"]), "bucket name"
    assert env["AWS_ENDPOINT_URL"].startswith("http://minio:"), "endpoint"
    assert env["AWS_SECRET_ACCESS_KEY"] == services["minio"]["environment"]["MINIO_ROOT_PASSWORD"]
print("docker/compose.distributed.yaml: ok")

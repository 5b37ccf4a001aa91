"""A stand-in for ``pip install --target DIR``: prints pip-like lines and writes a small package.

``--fail`` ends like pip does when it finds no matching distribution; ``--sleep S`` keeps it
running for S seconds before it writes anything (to cancel it meanwhile).
"""

import argparse
import os
import sys
import time

parser = argparse.ArgumentParser()
parser.add_argument("--target", required=True)
parser.add_argument("--fail", action="store_true")
parser.add_argument("--sleep", type=float, default=0.0)
args = parser.parse_args()

print("Collecting torch==2.13.0", flush=True)
if args.fail:
    print("ERROR: No matching distribution found for torch==2.13.0", flush=True)
    sys.exit(1)
print("  Downloading torch-2.13.0-cp311-none-linux_x86_64.whl (190.2 MB)", flush=True)
time.sleep(args.sleep)
package = os.path.join(args.target, "strnn_fake_pkg")
os.makedirs(package)
with open(os.path.join(package, "__init__.py"), "w") as f:
    f.write("VERSION = 2\n")
print("Successfully installed strnn_fake_pkg", flush=True)

"""Make docs/images/live_view.png: the 15-fish pyramid of experiments/formation.toml forming
in real time, seen in the live view by headless Chromium (as tests/cli/test_view.py sees it).

Run from the top of a checkout with the dev extras installed and Debian's chromium:
``python docs/view_picture.py [--after SECONDS] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

# The test suite's browser and process helpers, from the checkout this script lives in.
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tests.cli.browser import open_page, screenshot, wait_for_fish
from tests.conftest import Lines, free_port


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument("--after", type=float, default=30.0, help="seconds into the run")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("docs/images/live_view.png"),
        help="the screenshot to write (default: %(default)s)",
    )
    args = parser.parse_args()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    fishswarm = [sys.executable, "-m", "fishswarm"]
    run = subprocess.Popen(
        [*fishswarm, "run", "--config", "experiments/formation.toml", "--time", "realtime",
         "--duration", str(args.after + 60), "--quiet", "--listen", endpoint,
         "--record", "/tmp/live_view_picture.mcap", "--summary", "/tmp/live_view_picture.json"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    view = subprocess.Popen(
        [*fishswarm, "view", "--connect", endpoint, "--web-port", str(free_port()),
         "--grpc-port", str(free_port())],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    lines = Lines(view)
    try:
        url = lines.wait_for(r"^open (\S+) in a browser")[1]
        started = time.monotonic()
        with open_page(url) as page:
            wait_for_fish(page, args.out)
            time.sleep(max(0.0, args.after - (time.monotonic() - started)))
            screenshot(page, args.out)
        print(f"wrote {args.out}")
    finally:
        for process in (view, run):
            process.kill()
            process.wait(timeout=10)
        lines.close()


if __name__ == "__main__":
    main()

#!/usr/bin/env python
"""Serve a few synthetic completed frames with ``RerunLogger(serve=True)`` and screenshot the bundled Rerun web
viewer in headless Chromium (Debian's /usr/bin/chromium through playwright, as the viewer tests drive it).

    python scripts/rerun-live-screenshot.py [--out docs/guides/rerun-live.png] [--wait 20]

Needs rerun-sdk, playwright and Chromium (scripts/setup-browser.sh); no internet. WebGL runs on SwiftShader
(software), so the first frame can take a while to draw.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import numpy as np

from semattnet.robotics.rerun import RerunLogger

ARGS = ["--headless=new", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
        "--ignore-gpu-blocklist", "--disable-background-networking", "--no-first-run"]  # fmt: skip
H, W = 120, 400
K = np.array([[200.0, 0, W / 2], [0, 200.0, 40.0], [0, 0, 1]])
T_CAM_LIDAR = np.array([[0.0, -1, 0, 0], [0, 0, -1, -0.1], [1, 0, 0, -0.3], [0, 0, 0, 1]])


def synthetic_frame(i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rgb, sparse, depth) of a road scene: a ground plane 1.7 m below the camera and a wall 30 m ahead."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float32)
    ground = np.where(v > K[1, 2] + 1, 1.7 * K[1, 1] / np.maximum(v - K[1, 2], 1e-3), np.inf)
    depth = np.minimum(ground, 30.0 - 2.0 * i).astype(np.float32)
    rgb = np.stack([(u / W * 255), (v / H * 255), np.full_like(u, 90 + 40 * i)], -1).astype(np.uint8)
    rgb[depth < 29 - 2 * i] = (rgb[depth < 29 - 2 * i] * 0.5 + [60, 110, 60]).astype(np.uint8)
    sparse = np.where((v.astype(int) % 8 == 0) & (u.astype(int) % 3 == 0), depth, 0).astype(np.float32)
    return rgb, sparse, depth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/guides/rerun-live.png"))
    parser.add_argument("--wait", type=float, default=20.0, help="seconds to let the viewer draw")
    args = parser.parse_args()
    from playwright.sync_api import sync_playwright

    chromium = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if chromium is None:
        raise SystemExit("no Chromium: run scripts/setup-browser.sh")
    log = RerunLogger(serve=True, grpc_port=0, web_port=0)
    print(f"viewer: {log.url}")
    for i in range(3):
        rgb, sparse, depth = synthetic_frame(i)
        log.log_frame(1_700_000_000_000_000_000 + i * 100_000_000, rgb, K, T_CAM_LIDAR, sparse=sparse, depth=depth)
    errors: list[str] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.goto(str(log.url))
        page.wait_for_selector("canvas", timeout=60_000)
        time.sleep(args.wait)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(args.out))
        browser.close()
    log.close()
    print(f"wrote {args.out}" + (f"; console errors: {errors[:5]}" if errors else ""))


if __name__ == "__main__":
    main()

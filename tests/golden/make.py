"""The fixed messages behind the golden files, and ``python -m tests.golden.make`` to rewrite them.

Rewrite only on purpose (a new schema version): tests/test_protocol_golden.py fails whenever
encoding one of these messages no longer gives the bytes in the file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from protocol import (Attitude, CameraInfo, FeatureSet, Hint, ImageFrame, Payload, PoseEstimate, Stats, encode)

GOLDEN_DIR = Path(__file__).resolve().parent
STAMP_NS = 1_700_000_000_123_456_789

CAMERA = CameraInfo(fx=800.0, fy=810.0, cx=320.0, cy=240.0, width=4, height=3,
                    distortion=(-0.1, 0.01, 0.0, 0.0, 0.0), world_from_camera=(0.5, 0.0, 0.0, 0.0, 0.0, 1.5707963267948966))
#: A 1x1 grey PNG (8-bit greyscale), written by hand.
PNG_1X1 = bytes.fromhex("89504e470d0a1a0a0000000d49484452000000010000000108000000003a7e9b55"
                        "0000000a4944415478da6368000000820081da45083b0000000049454e44ae426082")


def golden_messages() -> dict[str, Payload]:
    """Name of each golden file (without ``.bin``) -> the message it holds."""
    camera_1x1 = CAMERA.model_copy(update={"width": 1, "height": 1})
    return {
        "hint": Hint(pose=(1.5, -2.0, 10.25, 0.125, -0.25, 3.0)),
        "features": FeatureSet.from_array(np.array([[320.5, 240.25], [10.0, 20.0], [639.0, 0.5]]), CAMERA,
                                          sender="uav1", seq=7, stamp_ns=STAMP_NS,
                                          labels=np.array([0, 3, 1])).model_copy(
            update={"best": (0.5, -0.25, 0.0, 0.0, 0.0, 0.75)}),
        "image_raw": ImageFrame.from_array(np.arange(36, dtype=np.uint8).reshape(3, 4, 3), CAMERA,
                                           sender="uav1", seq=8, stamp_ns=STAMP_NS),
        "image_png": ImageFrame(sender="uav1", seq=9, stamp_ns=STAMP_NS, camera=camera_1x1, encoding="png",
                                width=1, height=1, channels=1, data=PNG_1X1),
        "attitude": Attitude(sender="airship", seq=42, stamp_ns=STAMP_NS, body="airship", roll=0.1, pitch=-0.05,
                             yaw=1.0, sigma=(0.002, 0.002, 0.01)),
        "pose": PoseEstimate(sender="ugv2", seq=3, stamp_ns=STAMP_NS, target="airship",
                             pose=(1.0, 2.0, 15.0, 0.1, -0.05, 1.0), fitness=0.75, mismatch=0.1, converged=True,
                             generations=17, seconds=0.42, from_hint=True, inputs=("uav1",), good=True,
                             covariance=tuple(float(v) for v in np.diag([1e-4, 1e-4, 4e-4, 1e-5, 1e-5, 2e-5]).ravel())),
        "stats": Stats(sender="ugv2", seq=0, stamp_ns=STAMP_NS, sent={"pose": 10, "hint": 10},
                       received={"features": 9}, bytes_sent={"pose": 2670, "hint": 240},
                       bytes_received={"features": 4200}, rejected={"malformed": 1}),
    }


def golden_path(name: str) -> Path:
    return GOLDEN_DIR / f"{name}.bin"


#: The previous schema version's files, kept to show it is still decoded (docs/protocol.md §6): name -> the message
#: it decodes to. Version 2's ``pose`` carried the good verdict as ``confident``.
PREVIOUS = {"pose_v2": "pose"}


def main() -> None:
    for name, message in golden_messages().items():
        golden_path(name).write_bytes(encode(message))
        print(f"wrote {golden_path(name)} ({len(encode(message))} bytes)")


if __name__ == "__main__":
    main()

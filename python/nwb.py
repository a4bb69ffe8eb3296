"""Writes a mousepose run as NWB with the ndx-pose extension (run by `mousepose export nwb`).

Usage: python nwb.py POSES_CSV META_JSON OUT_NWB

META_JSON (written by mousepose) holds the session and subject metadata, the joint names in
order, the skeleton's edges (pairs of joint indices), the cameras (with their calibration
when the run has one), the videos to link, the software version and the models. Positions
are stored in millimetres with conversion 0.001 to metres; a joint without an estimate is
NaN; confidence is the joint's score. Each frame's status, orientation confidence and the
source of each joint go to the `PoseFrames` table beside the PoseEstimation.

A run of several mice (`poses.csv` with a `mouse` column) gets one PoseEstimation per mouse,
`mouse1`, `mouse2`, ..., each with its skeleton of that name and its `PoseFrames_mouse1`, ...
table (with `identity_confidence`); META_JSON's `mouse` set to k writes mouse k alone, as a
run of one mouse is written (what `export nwb --per-mouse` writes a file of each).
"""

import csv
import json
import math
import os
import subprocess
import sys
from datetime import datetime

import numpy as np
from hdmf.common import DynamicTable, VectorData
from ndx_pose import CalibratedCamera, PoseEstimation, PoseEstimationSeries, Skeleton, Skeletons
from pynwb import NWBHDF5IO, NWBFile
from pynwb.file import Subject
from pynwb.image import ImageSeries


def video_frames(path):
    """The video's frame times (s, from its first frame) and its width and height, by ffprobe."""
    out = subprocess.run(
        ["ffprobe", "-v", "error", "-select_streams", "v:0", "-show_entries",
         "packet=pts_time:stream=width,height", "-of", "json", path],
        check=True, capture_output=True, text=True,
    )
    probe = json.loads(out.stdout)
    stream = probe["streams"][0]
    times = sorted(float(p["pts_time"]) for p in probe.get("packets", []) if p.get("pts_time") not in (None, "N/A"))
    if not times:
        raise SystemExit(f"{path}: ffprobe finds no video frames in it")
    return np.array(times, dtype=np.float64) - times[0], [int(stream["width"]), int(stream["height"])]


def moseq_times(path, frames, t0_ns):
    """The device times of a MoSeq layout's video (`depth.avi` -> `depth_ts.txt`, first column,
    ms), in seconds from `t0_ns`, when that file is there with a line per frame; else None."""
    stem, _ = os.path.splitext(path)
    ts = f"{stem}_ts.txt"
    if not os.path.isfile(ts):
        return None
    with open(ts, encoding="utf-8") as f:
        lines = [line.split() for line in f if line.strip()]
    if len(lines) != frames:
        return None
    # Milliseconds with six decimals: whole nanoseconds, kept exact.
    def ns(text):
        whole, _, frac = text.partition(".")
        return int(whole) * 1_000_000 + int((frac + "000000")[:6])
    return np.array([(ns(cols[0]) - t0_ns) / 1e9 for cols in lines], dtype=np.float64)


def linked_video(nwb, name, video, out, t0_ns, description):
    """An ImageSeries in /acquisition pointing at `video` by its path relative to the NWB file.
    Its frame times: a MoSeq layout's time file beside it, else the video's own from its
    first frame, that frame at `start_s`; a constant rate is stored as a rate."""
    times, size = video_frames(video["path"])
    exact = moseq_times(video["path"], len(times), t0_ns)
    times = exact if exact is not None else times + video["start_s"]
    rel = os.path.relpath(os.path.abspath(video["path"]), os.path.dirname(os.path.abspath(out)))
    steps = np.unique(np.round(np.diff(times), decimals=9))
    timing = (
        dict(starting_time=float(times[0]), rate=float(1.0 / steps[0]))
        if len(times) > 2 and steps.size == 1 and steps[0] > 0
        else dict(timestamps=times)
    )
    series = ImageSeries(
        name=name,
        description=description,
        unit="n/a",
        format="external",
        external_file=[rel],
        starting_frame=[0],
        dimension=size,
        **timing,
    )
    nwb.add_acquisition(series)
    return series


def number(text):
    return float(text) if text != "" else math.nan


def pose_of(rows, meta, t0, device, source_video, labeled_video, name=None, identity=False):
    """One mouse's skeleton (named `name`, or mouse), PoseEstimation (named `name`, or
    PoseEstimation for a file's only mouse) and frames' table (with `identity_confidence`
    when `identity`)."""
    joints = meta["joints"]
    timestamps = np.array([(int(r["depth_device_ns"]) - t0) / 1e9 for r in rows], dtype=np.float64)
    skeleton = Skeleton(
        name=name or "mouse",
        nodes=joints,
        edges=np.array(meta["edges"], dtype=np.uint8),
    )
    series = []
    for k, joint in enumerate(joints):
        data = np.array(
            [[number(r[f"{joint}_x"]), number(r[f"{joint}_y"]), number(r[f"{joint}_z"])] for r in rows],
            dtype=np.float64,
        )
        confidence = np.array([number(r[f"{joint}_score"]) for r in rows], dtype=np.float64)
        series.append(
            PoseEstimationSeries(
                name=joint,
                description=f"joint {k + 1}, {joint}: position in the cage's world frame (origin on the glass, z up)",
                data=data,
                unit="meters",
                conversion=0.001,
                reference_frame="the cage's world frame: origin on the glass floor's top surface, z up, millimetres scaled by conversion",
                timestamps=timestamps if k == 0 else series[0],
                confidence=np.nan_to_num(confidence, nan=0.0),
                confidence_definition="the joint's score in [0, 1] (0 where the joint has no estimate)",
            )
        )
    estimation = PoseEstimation(
        name=name or "PoseEstimation",
        source_video=source_video,
        labeled_video=labeled_video,
        pose_estimation_series=series,
        description=meta["description"],
        scorer=meta["scorer"],
        source_software="mousepose",
        source_software_version=meta["software_version"],
        skeleton=skeleton,
        device=device,
    )

    # What poses.csv says of each frame beyond the positions: one row per frame, in the
    # series' order.
    def seq(text):
        return int(text) if text != "" else -1

    columns = [
        VectorData(name="timestamp", description="seconds, as the PoseEstimationSeries' timestamps", data=timestamps),
        VectorData(name="depth_seq", description="the depth camera's frame counter", data=np.array([seq(r["depth_seq"]) for r in rows], dtype=np.int64)),
        VectorData(name="color_seq", description="the colour camera's frame counter of the pair, -1 for a depth-only frame", data=np.array([seq(r["color_seq"]) for r in rows], dtype=np.int64)),
        VectorData(name="status", description="ok (joints estimated) or no_mouse", data=[r["status"] for r in rows]),
        VectorData(
            name="orientation_confidence",
            description="how sure the orientation tracker is of which end of the mouse is the head, 0.5 (a guess) to 1; NaN without a mouse",
            data=np.array([number(r.get("orientation_confidence") or "") for r in rows], dtype=np.float64),
        ),
        VectorData(
            name="joint_source",
            description="per joint in the skeleton's node order, where its position comes from: depth (the top depth image), paw (a detection in the bottom colour image), ik (inverse kinematics), default (the model's rest pose) or missing",
            data=[[r[f"{joint}_source"] for joint in joints] for r in rows],
        ),
    ]
    if identity:
        columns.append(
            VectorData(
                name="identity_confidence",
                description="how sure the mouse's number is in the frame, 0-1 (0 where it was not found)",
                data=np.array([number(r["identity_confidence"]) for r in rows], dtype=np.float64),
            )
        )
    frames = DynamicTable(
        name=f"PoseFrames_{name}" if name else "PoseFrames",
        description="per frame of the PoseEstimation series (same rows, same order): how each pose was made",
        columns=columns,
    )
    return skeleton, estimation, frames


def main(poses_csv, meta_json, out):
    with open(meta_json, encoding="utf-8") as f:
        meta = json.load(f)
    with open(poses_csv, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit(f"{poses_csv} has no rows")
    t0 = int(rows[0]["depth_device_ns"])
    # One mouse's rows (all of them in a run of one), by number.
    mice = {}
    for r in rows:
        mice.setdefault(int(r["mouse"]) if "mouse" in r else 1, []).append(r)
    alone = meta.get("mouse")
    if alone is not None:
        if alone not in mice:
            raise SystemExit(f"{poses_csv} has no mouse {alone}")
        mice = {alone: mice[alone]}
    start = datetime.fromisoformat(meta["session_start_time"].replace("Z", "+00:00"))
    nwb = NWBFile(
        session_description=meta["session_description"],
        identifier=meta["identifier"],
        session_start_time=start,
        experimenter=meta.get("experimenter") or None,
        lab=meta.get("lab") or None,
        institution=meta.get("institution") or None,
        source_script=meta["source_script"],
        experiment_description=meta["description"],
        keywords=["pose estimation", "mouse", "depth camera", "3D skeleton", "mousepose"],
        source_script_file_name="mousepose",
    )
    s = meta["subject"]
    born = s.get("date_of_birth")
    nwb.subject = Subject(
        subject_id=s["subject_id"],
        species=s["species"],
        sex=s["sex"],
        age=s.get("age") or None,
        date_of_birth=datetime.fromisoformat(born) if born else None,
        strain=s.get("strain") or None,
        genotype=s.get("genotype") or None,
        weight=s.get("weight") or None,
        description=s.get("description") or None,
    )
    # Each camera a Device with its serial number, linked to a DeviceModel (its model and
    # maker), as NWB 2.9 has them (a Device's own `manufacturer` is deprecated); a camera the
    # run's rig calibration covers is an ndx-pose CalibratedCamera holding it.
    models = {}
    for d in meta["devices"]:
        if d["model"] not in models:
            models[d["model"]] = nwb.create_device_model(
                name=d["model"],
                manufacturer=d["manufacturer"],
                description=f"camera model {d['model']}",
            )
    devices = []
    for d in meta["devices"]:
        common = dict(
            name=d["name"],
            description=d["description"],
            serial_number=d.get("serial_number") or None,
            model=models[d["model"]],
        )
        c = d.get("calibration")
        if c is None:
            devices.append(nwb.create_device(**common))
            continue
        camera = CalibratedCamera(
            **common,
            intrinsic_matrix=np.array(c["intrinsic_matrix"], dtype=np.float64),
            rotation_matrix=np.array(c["rotation_matrix"], dtype=np.float64),
            translation_vector=np.array(c["translation_vector"], dtype=np.float64),
            distortion_coefficients=np.array(c["distortion_coefficients"], dtype=np.float64),
        )
        nwb.add_device(camera)
        devices.append(camera)
    videos = meta.get("videos") or {}
    source_video = labeled_video = None
    if videos.get("source"):
        source_video = linked_video(
            nwb, "source_video", videos["source"], out, t0,
            "the video the poses were estimated from (external file, path relative to this file)",
        )
    if videos.get("labeled"):
        labeled_video = linked_video(
            nwb, "labeled_video", videos["labeled"], out, t0,
            "the poses drawn over the frames (mousepose export video; external file, path relative to this file)",
        )
    behavior = nwb.create_processing_module(name="behavior", description="3D pose of the mouse from mousepose")
    # ndx-pose links one camera to a PoseEstimation: the depth camera, whose image gives the
    # body (the bottom camera, which gives the paws, is among the file's devices).
    device = next((d for d in devices if d.name == "depth_camera"), devices[0])
    poses = [
        pose_of(
            mouse_rows, meta, t0, device, source_video, labeled_video,
            name=f"mouse{k}" if len(mice) > 1 else None,
            identity=len(mice) > 1 or alone is not None,
        )
        for k, mouse_rows in sorted(mice.items())
    ]
    behavior.add(Skeletons(skeletons=[skeleton for skeleton, _, _ in poses]))
    for _, estimation, frames in poses:
        behavior.add(estimation)
        behavior.add(frames)
    with NWBHDF5IO(out, mode="w") as io:
        io.write(nwb)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    main(*sys.argv[1:])

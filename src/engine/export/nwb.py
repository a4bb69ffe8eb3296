"""Writes a mousepose run as NWB with the ndx-pose extension (run by `mousepose export nwb`).

Usage: python nwb.py POSES_CSV META_JSON OUT_NWB

META_JSON (written by mousepose) holds the session and subject metadata, the joint names in
order, the skeleton's edges (pairs of joint indices), the cameras, the software version and
the models. Positions are stored in millimetres with conversion 0.001 to metres; a joint
without an estimate is NaN; confidence is the joint's score.
"""

import csv
import json
import math
import sys
from datetime import datetime

import numpy as np
from ndx_pose import PoseEstimation, PoseEstimationSeries, Skeleton, Skeletons
from pynwb import NWBHDF5IO, NWBFile
from pynwb.file import Subject


def main(poses_csv, meta_json, out):
    with open(meta_json, encoding="utf-8") as f:
        meta = json.load(f)
    joints = meta["joints"]
    with open(poses_csv, newline="", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        raise SystemExit(f"{poses_csv} has no rows")
    t0 = int(rows[0]["depth_device_ns"])
    timestamps = np.array([(int(r["depth_device_ns"]) - t0) / 1e9 for r in rows], dtype=np.float64)

    def number(text):
        return float(text) if text != "" else math.nan

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
    # maker), as NWB 2.9 has them (a Device's own `manufacturer` is deprecated).
    models = {}
    for d in meta["devices"]:
        if d["model"] not in models:
            models[d["model"]] = nwb.create_device_model(
                name=d["model"],
                manufacturer=d["manufacturer"],
                description=f"camera model {d['model']}",
            )
    devices = [
        nwb.create_device(
            name=d["name"],
            description=d["description"],
            serial_number=d.get("serial_number") or None,
            model=models[d["model"]],
        )
        for d in meta["devices"]
    ]
    skeleton = Skeleton(
        name="mouse",
        nodes=joints,
        edges=np.array(meta["edges"], dtype=np.uint8),
    )
    series = []
    for k, name in enumerate(joints):
        data = np.array(
            [[number(r[f"{name}_x"]), number(r[f"{name}_y"]), number(r[f"{name}_z"])] for r in rows],
            dtype=np.float64,
        )
        confidence = np.array([number(r[f"{name}_score"]) for r in rows], dtype=np.float64)
        series.append(
            PoseEstimationSeries(
                name=name,
                description=f"joint {k + 1}, {name}: position in the cage's world frame (origin on the glass, z up)",
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
        name="PoseEstimation",
        pose_estimation_series=series,
        description=meta["description"],
        scorer=meta["scorer"],
        source_software="mousepose",
        source_software_version=meta["software_version"],
        skeleton=skeleton,
        # ndx-pose links one camera to a PoseEstimation: the depth camera, whose image gives
        # the body (the bottom camera, which gives the paws, is among the file's devices).
        device=next((d for d in devices if d.name == "depth_camera"), devices[0]),
    )
    behavior = nwb.create_processing_module(name="behavior", description="3D pose of the mouse from mousepose")
    behavior.add(Skeletons(skeletons=[skeleton]))
    behavior.add(estimation)
    with NWBHDF5IO(out, mode="w") as io:
        io.write(nwb)


if __name__ == "__main__":
    if len(sys.argv) != 4:
        raise SystemExit(__doc__)
    main(*sys.argv[1:])

#!/usr/bin/env python3
"""Converts GTSAM's 2-D example graphs (borglab/gtsam, examples/Data, BSD) into the g2o files
of this folder (see ATTRIBUTION.md). Needs the gtsam package (scripts/python-env.sh) for the
pose arithmetic. Usage: convert.py GTSAM_EXAMPLES_DATA_DIR"""
import os
import sys

import gtsam
import numpy as np

LANDMARK_ID_OFFSET = 100_000


def num(x):
    return repr(float(x))


def edge_line(i, j, z, info):
    upper = [info[0, 0], info[0, 1], info[0, 2], info[1, 1], info[1, 2], info[2, 2]]
    return "EDGE_SE2 %d %d %s" % (i, j, " ".join(num(v) for v in [z.x(), z.y(), z.theta()] + upper))


def toro_info(v):
    # gtsam.load2D's NoiseFormatAUTO (dataset.cpp createNoiseModel): v = (v0..v5) is read as a
    # TORO-ordered covariance [v0 v1 v4; v1 v2 v5; v4 v5 v3] when v1 = v4 = v5 = 0 and v0, v2,
    # v3 != 0, and as a g2o-ordered covariance [v0 v1 v2; v1 v3 v4; v2 v4 v5] when v1 = v2 = v4 = 0.
    if v[0] and not v[1] and v[2] and v[3] and not v[4] and not v[5]:
        cov = np.array([[v[0], v[1], v[4]], [v[1], v[2], v[5]], [v[4], v[5], v[3]]])
    elif v[0] and not v[1] and not v[2] and v[3] and not v[4] and v[5]:
        cov = np.array([[v[0], v[1], v[2]], [v[1], v[3], v[4]], [v[2], v[4], v[5]]])
    else:
        raise ValueError("unrecognised covariance layout %r" % (v,))
    return np.linalg.inv(cov)


def convert(lines, max_pose, vertices_from_file):
    """TORO-style lines (VERTEX2, EDGE2/ODOMETRY, LANDMARK) to g2o lines, poses < max_pose.
    Initial poses: the file's VERTEX2, else composed along the edges in file order as
    gtsam.load2D does; landmarks at their first sighting."""
    poses, points, edges, observations = {}, {}, [], []
    for line in lines:
        f = line.split()
        if not f:
            continue
        if f[0] == "VERTEX2" and vertices_from_file:
            i = int(f[1])
            if i < max_pose:
                poses[i] = gtsam.Pose2(*map(float, f[2:5]))
        elif f[0] in ("EDGE2", "ODOMETRY"):
            i, j = int(f[1]), int(f[2])
            if i >= max_pose or j >= max_pose:
                continue
            z = gtsam.Pose2(*map(float, f[3:6]))
            edges.append((i, j, z, toro_info([float(x) for x in f[6:12]])))
            if not vertices_from_file:
                poses.setdefault(i, gtsam.Pose2())
                poses.setdefault(j, poses[i].compose(z))
        elif f[0] == "LANDMARK":
            i, l = int(f[1]), int(f[2]) + LANDMARK_ID_OFFSET
            if i >= max_pose:
                continue
            xy = np.array([float(f[3]), float(f[4])])
            # The reading's 2x2 covariance [v1 v2; v2 v3] (m^2), inverted.
            info = np.linalg.inv(np.array([[float(f[5]), float(f[6])], [float(f[6]), float(f[7])]]))
            observations.append((i, l, xy, info))
            points.setdefault(l, poses[i].transformFrom(xy))
    out = ["VERTEX_SE2 %d %s %s %s" % (i, num(p.x()), num(p.y()), num(p.theta())) for i, p in sorted(poses.items())]
    out += ["VERTEX_XY %d %s %s" % (l, num(p[0]), num(p[1])) for l, p in sorted(points.items())]
    out += [edge_line(*e) for e in edges]
    out += [
        "EDGE_SE2_XY %d %d %s %s %s %s %s" % (i, l, num(xy[0]), num(xy[1]), num(m[0, 0]), num(m[0, 1]), num(m[1, 1]))
        for i, l, xy, m in observations
    ]
    return "\n".join(out) + "\n"


def main():
    src = sys.argv[1]
    here = os.path.dirname(os.path.abspath(__file__))
    read = lambda name: open(os.path.join(src, name)).read().splitlines()
    with open(os.path.join(here, "noisyToyGraph.g2o"), "w") as f:
        f.write(open(os.path.join(src, "noisyToyGraph.txt")).read())
    with open(os.path.join(here, "w100.g2o"), "w") as f:
        f.write(convert(read("w100.graph"), 10**9, True))
    with open(os.path.join(here, "w20000-3500.g2o"), "w") as f:
        f.write(convert(read("w20000.txt"), 3500, False))
    with open(os.path.join(here, "victoria_park-1000.g2o"), "w") as f:
        f.write(convert(read("victoria_park.txt"), 1000, False))


if __name__ == "__main__":
    main()

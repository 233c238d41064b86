#!/usr/bin/env python3
"""GTSAM's optimum of a 2-D g2o graph, the reference processes/localization/tests/g2o.rs
compares GraphSLAM's with (algorithms §6.9.4, "g2o graphs and GTSAM").

Usage: scripts/gtsam-reference.py DATA.g2o   (target/python-env/bin/python3 has gtsam:
scripts/python-env.sh installs it)

Prints one JSON object: the gtsam version, vertex and factor counts, the initial and final
error (GTSAM's, 0.5 * sum of e' * Omega * e over all factors), the LM iterations, the seconds the
optimisation took, the optimised poses {id: [x, y, theta]} and points {id: [x, y]}, and each
vertex's marginal standard deviations at the optimum (gtsam.Marginals), {id: [sx, sy, stheta]}
and {id: [sx, sy]}: where a graph is weakly constrained two optimisers stop at different points of
a nearly flat valley, and the difference means something only against these.

The graph is the one mole builds from the same file:
- gtsam.readG2o(is3D=False) gives the VERTEX_SE2 poses (key = id), the VERTEX_XY points
  (key = L(id)) and one BetweenFactorPose2 per EDGE_SE2 (information as given).
- readG2o does not read EDGE_SE2_XY (it takes only BR and LANDMARK tags, as bearing-range), so
  each EDGE_SE2_XY is added here as a factor on the point in the pose frame,
  e = pose.transformTo(point) - z, with the edge's information: g2o's meaning of the edge.
- readG2o ignores FIX: the gauge is anchored as mole anchors it, a PriorFactorPose2 at the
  initial value with sigma 1e-3 (m, m, rad) on each FIXed pose, else on the first VERTEX_SE2.
Then Levenberg-Marquardt runs to convergence (relative and absolute error decrease 1e-12).
"""
import json
import sys
import time

import gtsam
import numpy as np

# mole's graph_slam::DEFAULT_PRIOR_STD.
PRIOR_STD = 1e-3
TOLERANCE = 1e-12
MAX_ITERATIONS = 1000


def point_in_pose_frame(measured):
    """The error function of a CustomFactor on (Pose2, Point2): R(theta)' (p - t) - z, with the
    Jacobians in GTSAM's tangent spaces (those of Pose2.transformTo)."""

    def error(this, values, jacobians):
        pose = values.atPose2(this.keys()[0])
        point = values.atPoint2(this.keys()[1])
        q = pose.transformTo(point)
        if jacobians is not None:
            c, s = np.cos(pose.theta()), np.sin(pose.theta())
            jacobians[0] = np.array([[-1.0, 0.0, q[1]], [0.0, -1.0, -q[0]]])
            jacobians[1] = np.array([[c, s], [-s, c]])
        return q - measured

    return error


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: gtsam-reference.py DATA.g2o")
    path = sys.argv[1]
    graph, initial = gtsam.readG2o(path, False)

    first_pose, fixed, landmark_edges = None, [], 0
    with open(path) as f:
        for line in f:
            fields = line.split()
            if not fields:
                continue
            if fields[0] == "VERTEX_SE2" and first_pose is None:
                first_pose = int(fields[1])
            elif fields[0] == "FIX":
                fixed += [int(x) for x in fields[1:]]
            elif fields[0] == "EDGE_SE2_XY":
                i, j = int(fields[1]), int(fields[2])
                dx, dy, i11, i12, i22 = map(float, fields[3:8])
                model = gtsam.noiseModel.Gaussian.Information(np.array([[i11, i12], [i12, i22]]))
                graph.add(
                    gtsam.CustomFactor(
                        model, [i, gtsam.symbol("l", j)], point_in_pose_frame(np.array([dx, dy]))
                    )
                )
                landmark_edges += 1
    anchors = fixed or [first_pose]
    prior = gtsam.noiseModel.Diagonal.Sigmas(np.full(3, PRIOR_STD))
    for key in dict.fromkeys(anchors):
        graph.add(gtsam.PriorFactorPose2(key, initial.atPose2(key), prior))

    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(TOLERANCE)
    params.setAbsoluteErrorTol(TOLERANCE)
    params.setMaxIterations(MAX_ITERATIONS)
    initial_error = graph.error(initial)
    start = time.perf_counter()
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
    result = optimizer.optimize()
    seconds = time.perf_counter() - start

    marginals = gtsam.Marginals(graph, result)
    poses, points, sigmas, point_sigmas = {}, {}, {}, {}
    for key in result.keys():
        symbol = gtsam.Symbol(key)
        std = [float(x) for x in np.sqrt(np.diag(marginals.marginalCovariance(key)))]
        if symbol.chr() == ord("l"):
            p = result.atPoint2(key)
            points[str(symbol.index())] = [float(p[0]), float(p[1])]
            point_sigmas[str(symbol.index())] = std
        else:
            p = result.atPose2(key)
            poses[str(key)] = [p.x(), p.y(), p.theta()]
            # Pose2's tangent is (x, y, theta) in the pose frame: rotate the position's
            # deviations into the map frame's axes only in size (the larger of the two serves
            # both), as the comparison is per coordinate.
            std[0] = std[1] = max(std[0], std[1])
            sigmas[str(key)] = std
    print(
        json.dumps(
            {
                "gtsam": getattr(gtsam, "__version__", None) or _version(),
                "file": path,
                "poses_count": len(poses),
                "points_count": len(points),
                "factors": graph.size(),
                "landmark_edges": landmark_edges,
                "anchors": anchors,
                "initial_error": initial_error,
                "final_error": graph.error(result),
                "iterations": optimizer.iterations(),
                "seconds": seconds,
                "poses": poses,
                "points": points,
                "sigmas": sigmas,
                "point_sigmas": point_sigmas,
            }
        )
    )


def _version():
    from importlib.metadata import version

    return version("gtsam")


if __name__ == "__main__":
    main()

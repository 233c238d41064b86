"""mole's messages as ctypes structures, for processes written in Python.

Generated from shared-types/src/layout.rs: do not edit. Regenerate it with
`MOLE_BLESS=1 cargo test -p mole-types`; a test fails when this file and the Rust types differ.

Each class's type_name() is what the iceoryx2 Python package records as the service's payload
type, with ctypes.sizeof() and ctypes.alignment(): all three must equal the Rust side's, or
opening the service fails with incompatible types. Importing this module checks every size,
alignment and field offset against the Rust types.
"""

import ctypes
from typing import NamedTuple


def _check(cls, size, alignment, offsets):
    """Refuses to load when ctypes lays a class out otherwise than Rust does."""
    fields = [getattr(cls, name).offset for name, _ in cls._fields_]
    actual = (ctypes.sizeof(cls), ctypes.alignment(cls), fields)
    if actual != (size, alignment, offsets):
        raise TypeError(f"{cls.__name__}: ctypes {actual}, Rust {(size, alignment, offsets)}")


class Header(ctypes.Structure):
    """`mole.Header.v1`: 32 bytes, alignment 8."""

    _fields_ = [
        ("seq", ctypes.c_uint64),
        ("tick", ctypes.c_uint64),
        ("stamp_ns", ctypes.c_uint64),
        ("origin_ns", ctypes.c_uint64),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Header.v1"


_check(Header, 32, 8, [0, 8, 16, 24])


class RobotSpec(ctypes.Structure):
    """`mole.RobotSpec.v1`: 40 bytes, alignment 8."""

    _fields_ = [
        ("radius", ctypes.c_double),
        ("max_speed", ctypes.c_double),
        ("max_omega", ctypes.c_double),
        ("max_accel", ctypes.c_double),
        ("max_alpha", ctypes.c_double),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.RobotSpec.v1"


_check(RobotSpec, 40, 8, [0, 8, 16, 24, 32])


class SensorSpec(ctypes.Structure):
    """`mole.SensorSpec.v1`: 104 bytes, alignment 8."""

    _fields_ = [
        ("lidar_beams", ctypes.c_uint32),
        ("tactile_sensors", ctypes.c_uint32),
        ("lidar_range_max", ctypes.c_double),
        ("lidar_fov", ctypes.c_double),
        ("lidar_range_std", ctypes.c_double),
        ("tactile_stiffness", ctypes.c_double),
        ("tactile_force_std", ctypes.c_double),
        ("odom_v_std", ctypes.c_double),
        ("odom_omega_std", ctypes.c_double),
        ("beacon_range_max", ctypes.c_double),
        ("beacon_range_std", ctypes.c_double),
        ("beacon_bearing_std", ctypes.c_double),
        ("fix_std", ctypes.c_double),
        ("fix_period_ticks", ctypes.c_uint32),
        ("beacons_anonymous", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.SensorSpec.v1"


_check(SensorSpec, 104, 8, [0, 4, 8, 16, 24, 32, 40, 48, 56, 64, 72, 80, 88, 96, 100])


class Square(ctypes.Structure):
    """`mole.Square.v1`: 24 bytes, alignment 8."""

    _fields_ = [
        ("cx", ctypes.c_double),
        ("cy", ctypes.c_double),
        ("side", ctypes.c_double),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Square.v1"


_check(Square, 24, 8, [0, 8, 16])


class BeaconSite(ctypes.Structure):
    """`mole.BeaconSite.v1`: 24 bytes, alignment 8."""

    _fields_ = [
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("id", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.BeaconSite.v1"


_check(BeaconSite, 24, 8, [0, 8, 16, 20])


class WorldMap(ctypes.Structure):
    """`mole.WorldMap.v1`: 50200 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("arena_width", ctypes.c_double),
        ("arena_height", ctypes.c_double),
        ("dt", ctypes.c_double),
        ("seed", ctypes.c_uint64),
        ("start_x", ctypes.c_double),
        ("start_y", ctypes.c_double),
        ("start_theta", ctypes.c_double),
        ("goal_x", ctypes.c_double),
        ("goal_y", ctypes.c_double),
        ("goal_tolerance", ctypes.c_double),
        ("has_goal", ctypes.c_uint32),
        ("n_obstacles", ctypes.c_uint32),
        ("n_beacons", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("grid_resolution", ctypes.c_double),
        ("robot", RobotSpec),
        ("sensors", SensorSpec),
        ("obstacles", Square * 2048),
        ("beacons", BeaconSite * 32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.WorldMap.v1"


_check(WorldMap, 50200, 8, [
    0, 32, 40, 48, 56, 64, 72, 80, 88, 96, 104, 112, 116, 120, 124, 128, 136, 176, 280, 49432,
])


class Contact(ctypes.Structure):
    """`mole.Contact.v1`: 40 bytes, alignment 8."""

    _fields_ = [
        ("px", ctypes.c_double),
        ("py", ctypes.c_double),
        ("nx", ctypes.c_double),
        ("ny", ctypes.c_double),
        ("depth", ctypes.c_double),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Contact.v1"


_check(Contact, 40, 8, [0, 8, 16, 24, 32])


class Truth(ctypes.Structure):
    """`mole.Truth.v1`: 424 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("theta", ctypes.c_double),
        ("v", ctypes.c_double),
        ("omega", ctypes.c_double),
        ("penetration", ctypes.c_double),
        ("cmd_latency_ns", ctypes.c_uint64),
        ("flags", ctypes.c_uint32),
        ("end_reason", ctypes.c_uint32),
        ("n_contacts", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("contacts", Contact * 8),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Truth.v1"


_check(Truth, 424, 8, [0, 32, 40, 48, 56, 64, 72, 80, 88, 92, 96, 100, 104])


class Scan(ctypes.Structure):
    """`mole.Scan.v1`: 4144 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("angle_min", ctypes.c_float),
        ("angle_increment", ctypes.c_float),
        ("range_max", ctypes.c_float),
        ("n_beams", ctypes.c_uint32),
        ("ranges", ctypes.c_float * 1024),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Scan.v1"


_check(Scan, 4144, 8, [0, 32, 36, 40, 44, 48])


class TactileReading(ctypes.Structure):
    """`mole.TactileReading.v1`: 16 bytes, alignment 4."""

    _fields_ = [
        ("angle", ctypes.c_float),
        ("fx", ctypes.c_float),
        ("fy", ctypes.c_float),
        ("_pad", ctypes.c_float),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.TactileReading.v1"


_check(TactileReading, 16, 4, [0, 4, 8, 12])


class Tactile(ctypes.Structure):
    """`mole.Tactile.v1`: 552 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("n_sensors", ctypes.c_uint32),
        ("radius", ctypes.c_float),
        ("sensors", TactileReading * 32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Tactile.v1"


_check(Tactile, 552, 8, [0, 32, 36, 40])


class Odom(ctypes.Structure):
    """`mole.Odom.v2`: 80 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("theta", ctypes.c_double),
        ("v", ctypes.c_double),
        ("omega", ctypes.c_double),
        ("dt", ctypes.c_double),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Odom.v2"


_check(Odom, 80, 8, [0, 32, 40, 48, 56, 64, 72])


class BeaconReading(ctypes.Structure):
    """`mole.BeaconReading.v1`: 24 bytes, alignment 8."""

    _fields_ = [
        ("id", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("range", ctypes.c_double),
        ("bearing", ctypes.c_double),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.BeaconReading.v1"


_check(BeaconReading, 24, 8, [0, 4, 8, 16])


class Beacons(ctypes.Structure):
    """`mole.Beacons.v1`: 808 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("n_readings", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("readings", BeaconReading * 32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Beacons.v1"


_check(Beacons, 808, 8, [0, 32, 36, 40])


class Fix(ctypes.Structure):
    """`mole.Fix.v1`: 64 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("std", ctypes.c_double),
        ("valid", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Fix.v1"


_check(Fix, 64, 8, [0, 32, 40, 48, 56, 60])


class Pose(ctypes.Structure):
    """`mole.Pose.v2`: 168 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("theta", ctypes.c_double),
        ("covariance", ctypes.c_double * 9),
        ("odom", ctypes.c_double * 3),
        ("update_ns", ctypes.c_uint64),
        ("estimator", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Pose.v2"


_check(Pose, 168, 8, [0, 32, 40, 48, 56, 128, 152, 160, 164])


class Particle(ctypes.Structure):
    """`mole.Particle.v1`: 16 bytes, alignment 4."""

    _fields_ = [
        ("x", ctypes.c_float),
        ("y", ctypes.c_float),
        ("theta", ctypes.c_float),
        ("w", ctypes.c_float),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Particle.v1"


_check(Particle, 16, 4, [0, 4, 8, 12])


class Particles(ctypes.Structure):
    """`mole.Particles.v2`: 262184 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("n_particles", ctypes.c_uint32),
        ("n_filter", ctypes.c_uint32),
        ("particles", Particle * 16384),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Particles.v2"


_check(Particles, 262184, 8, [0, 32, 36, 40])


class Landmark(ctypes.Structure):
    """`mole.Landmark.v1`: 56 bytes, alignment 8."""

    _fields_ = [
        ("id", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("covariance", ctypes.c_double * 4),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Landmark.v1"


_check(Landmark, 56, 8, [0, 4, 8, 16, 24])


class Landmarks(ctypes.Structure):
    """`mole.Landmarks.v2`: 3632 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("n_landmarks", ctypes.c_uint32),
        ("estimator", ctypes.c_uint32),
        ("nees_dof", ctypes.c_double),
        ("landmarks", Landmark * 64),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Landmarks.v2"


_check(Landmarks, 3632, 8, [0, 32, 36, 40, 48])


class TrajectoryPose(ctypes.Structure):
    """`mole.TrajectoryPose.v1`: 16 bytes, alignment 4."""

    _fields_ = [
        ("tick_offset", ctypes.c_uint32),
        ("x", ctypes.c_float),
        ("y", ctypes.c_float),
        ("theta", ctypes.c_float),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.TrajectoryPose.v1"


_check(TrajectoryPose, 16, 4, [0, 4, 8, 12])


class Trajectory(ctypes.Structure):
    """`mole.Trajectory.v1`: 320048 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("first_tick", ctypes.c_uint64),
        ("n_poses", ctypes.c_uint32),
        ("estimator", ctypes.c_uint32),
        ("poses", TrajectoryPose * 20000),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Trajectory.v1"


_check(Trajectory, 320048, 8, [0, 32, 40, 44, 48])


class Grid(ctypes.Structure):
    """`mole.Grid.v1`: 262216 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("width", ctypes.c_uint32),
        ("height", ctypes.c_uint32),
        ("resolution", ctypes.c_double),
        ("origin_x", ctypes.c_double),
        ("origin_y", ctypes.c_double),
        ("kind", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("cells", ctypes.c_uint8 * 262144),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Grid.v1"


_check(Grid, 262216, 8, [0, 32, 36, 40, 48, 56, 64, 68, 72])


class Cmd(ctypes.Structure):
    """`mole.Cmd.v1`: 56 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("v", ctypes.c_double),
        ("omega", ctypes.c_double),
        ("mode", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Cmd.v1"


_check(Cmd, 56, 8, [0, 32, 40, 48, 52])


class PlanStatus(ctypes.Structure):
    """`mole.PlanStatus.v2`: 4184 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("mode", ctypes.c_uint32),
        ("flags", ctypes.c_uint32),
        ("goal_x", ctypes.c_double),
        ("goal_y", ctypes.c_double),
        ("frontier_x", ctypes.c_double),
        ("frontier_y", ctypes.c_double),
        ("bounces", ctypes.c_uint32),
        ("give_ups", ctypes.c_uint32),
        ("n_path", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("path", (ctypes.c_float * 2) * 512),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.PlanStatus.v2"


_check(PlanStatus, 4184, 8, [0, 32, 36, 40, 48, 56, 64, 72, 76, 80, 84, 88])


class Tick(ctypes.Structure):
    """`mole.Tick.v1`: 48 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("dt", ctypes.c_double),
        ("flags", ctypes.c_uint32),
        ("mode", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Tick.v1"


_check(Tick, 48, 8, [0, 32, 40, 44])


class TopicStats(ctypes.Structure):
    """`mole.TopicStats.v1`: 80 bytes, alignment 8."""

    _fields_ = [
        ("topic", ctypes.c_uint8 * 32),
        ("direction", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("count", ctypes.c_uint64),
        ("dropped", ctypes.c_uint64),
        ("invalid", ctypes.c_uint64),
        ("rate_hz", ctypes.c_float),
        ("latency_p50_us", ctypes.c_float),
        ("latency_p99_us", ctypes.c_float),
        ("latency_max_us", ctypes.c_float),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.TopicStats.v1"


_check(TopicStats, 80, 8, [0, 32, 36, 40, 48, 56, 64, 68, 72, 76])


class Stats(ctypes.Structure):
    """`mole.Stats.v2`: 1392 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("process", ctypes.c_uint8 * 32),
        ("pid", ctypes.c_uint32),
        ("n_topics", ctypes.c_uint32),
        ("cpu_ns", ctypes.c_uint64),
        ("max_rss_bytes", ctypes.c_uint64),
        ("steps", ctypes.c_uint64),
        ("step_cpu_ns", ctypes.c_uint64),
        ("system_ns", ctypes.c_uint64),
        ("topics", TopicStats * 16),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Stats.v2"


_check(Stats, 1392, 8, [0, 32, 64, 68, 72, 80, 88, 96, 104, 112])


class RunStatus(ctypes.Structure):
    """`mole.RunStatus.v1`: 56 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("coverage", ctypes.c_float),
        ("loop_p50_us", ctypes.c_float),
        ("loop_p99_us", ctypes.c_float),
        ("max_penetration_m", ctypes.c_float),
        ("rmse_m", ctypes.c_float),
        ("finished", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.RunStatus.v1"


_check(RunStatus, 56, 8, [0, 32, 36, 40, 44, 48, 52])


class ProcessStatus(ctypes.Structure):
    """`mole.ProcessStatus.v1`: 48 bytes, alignment 4."""

    _fields_ = [
        ("role", ctypes.c_uint8 * 32),
        ("pid", ctypes.c_uint32),
        ("state", ctypes.c_uint32),
        ("restarts", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.ProcessStatus.v1"


_check(ProcessStatus, 48, 4, [0, 32, 36, 40, 44])


class Processes(ctypes.Structure):
    """`mole.Processes.v1`: 808 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("n_processes", ctypes.c_uint32),
        ("_pad", ctypes.c_uint32),
        ("processes", ProcessStatus * 16),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Processes.v1"


_check(Processes, 808, 8, [0, 32, 36, 40])


class Goal(ctypes.Structure):
    """`mole.Goal.v1`: 56 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("x", ctypes.c_double),
        ("y", ctypes.c_double),
        ("tolerance", ctypes.c_double),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Goal.v1"


_check(Goal, 56, 8, [0, 32, 40, 48])


class Pace(ctypes.Structure):
    """`mole.Pace.v1`: 40 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("op", ctypes.c_uint32),
        ("steps", ctypes.c_uint32),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Pace.v1"


_check(Pace, 40, 8, [0, 32, 36])


class Fault(ctypes.Structure):
    """`mole.Fault.v1`: 112 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("id", ctypes.c_uint32),
        ("kind", ctypes.c_uint32),
        ("target", ctypes.c_uint8 * 32),
        ("start_ns", ctypes.c_uint64),
        ("end_ns", ctypes.c_uint64),
        ("delay_ns", ctypes.c_uint64),
        ("fraction", ctypes.c_double),
        ("seed", ctypes.c_uint64),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.Fault.v1"


_check(Fault, 112, 8, [0, 32, 36, 40, 72, 80, 88, 96, 104])


class ParamChange(ctypes.Structure):
    """`mole.ParamChange.v1`: 536 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("state", ctypes.c_uint32),
        ("request", ctypes.c_uint32),
        ("apply_at", ctypes.c_uint64),
        ("requested_ns", ctypes.c_uint64),
        ("role", ctypes.c_uint8 * 32),
        ("key", ctypes.c_uint8 * 96),
        ("value", ctypes.c_uint8 * 96),
        ("text", ctypes.c_uint8 * 256),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.ParamChange.v1"


_check(ParamChange, 536, 8, [0, 32, 36, 40, 48, 56, 88, 184, 280])


class ControlRequest(ctypes.Structure):
    """`mole.ControlRequest.v1`: 3144 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("op", ctypes.c_uint32),
        ("n_args", ctypes.c_uint32),
        ("role", ctypes.c_uint8 * 32),
        ("cwd", ctypes.c_uint8 * 1024),
        ("argv", ctypes.c_uint8 * 2048),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.ControlRequest.v1"


_check(ControlRequest, 3144, 8, [0, 32, 36, 40, 72, 1096])


class ControlResponse(ctypes.Structure):
    """`mole.ControlResponse.v2`: 8272 bytes, alignment 8."""

    _fields_ = [
        ("header", Header),
        ("status", ctypes.c_uint32),
        ("pid", ctypes.c_uint32),
        ("gap_ns", ctypes.c_uint64),
        ("period_ns", ctypes.c_uint64),
        ("steps_lost", ctypes.c_uint64),
        ("steps_repeated", ctypes.c_uint64),
        ("tick", ctypes.c_uint64),
        ("text", ctypes.c_uint8 * 8192),
    ]

    @classmethod
    def type_name(cls) -> str:
        return "mole.ControlResponse.v2"


_check(ControlResponse, 8272, 8, [0, 32, 36, 40, 48, 56, 64, 72, 80])


# The constants of shared-types/src/messages.rs.
MAX_OBSTACLES = 2048
MAX_BEACONS = 32
MAX_BEAMS = 1024
MAX_TACTILE = 32
MAX_CONTACTS = 8
MAX_GRID_CELLS = 262144
MAX_PARTICLES = 16384
MAX_LANDMARKS = 64
MAX_TRAJECTORY_POSES = 20000
MAX_PATH = 512
MAX_TOPIC_STATS = 16
NAME_LEN = 32
MAX_PROCESSES = 16
TRUTH_END = 1
TRUTH_GOAL_REACHED = 2
TRUTH_IN_CONTACT = 4
END_NONE = 0
LANDMARK_ANONYMOUS = 4294967295
GRID_FRONTIER = 0
GRID_CONTACT = 1
CELL_UNEXPLORED = 0
CELL_FREE = 1
CELL_OCCUPIED = 2
MODE_IDLE = 0
MODE_EXPLORE = 1
MODE_BOUNCE_BACK = 2
MODE_GOAL = 3
MODE_STALLED = 4
MODE_ESCAPE = 5
MODE_DONE = 6
MODE_ARRIVED = 7
STATUS_HAS_GOAL = 1
STATUS_HAS_FRONTIER = 2
STATUS_EXPLORATION_COMPLETE = 4
TICK_END = 1
DIRECTION_SUBSCRIBE = 0
DIRECTION_PUBLISH = 1
PROCESS_STARTING = 0
PROCESS_RUNNING = 1
PROCESS_RESTARTING = 2
PROCESS_EXITED = 3
PROCESS_FAILED = 4
PACE_RUN = 1
PACE_PAUSE = 2
PACE_STEP = 3
PACE_MAX_STEPS = 100000
END_TICKS = 1
END_GOAL_REACHED = 2
END_STOPPED = 3
END_EXPLORATION_COMPLETE = 4
ESTIMATOR_BAYES = 0
ESTIMATOR_KF = 1
ESTIMATOR_EKF = 2
ESTIMATOR_PF = 3
ESTIMATOR_EKF_SLAM = 4
ESTIMATOR_FASTSLAM = 5
ESTIMATOR_GRAPH_SLAM = 6
CLOCK_REALTIME = 0
CLOCK_LOCKSTEP = 1
FAULT_KILL = 1
FAULT_STOP = 2
FAULT_DELAY = 3
FAULT_DROP = 4
FAULT_CORRUPT = 5


class Topic(NamedTuple):
    """A topic: its name below the namespace, its message, and what its service holds."""

    name: str
    message: type
    history: int
    buffer: int
    max_publishers: int
    max_subscribers: int


WORLD_MAP = Topic(
    "world/map", WorldMap, history=1, buffer=2, max_publishers=2, max_subscribers=16
)

WORLD_TRUTH = Topic(
    "world/truth", Truth, history=1, buffer=64, max_publishers=2, max_subscribers=16
)

SENSING_SCAN = Topic(
    "sensing/scan", Scan, history=2, buffer=16, max_publishers=2, max_subscribers=16
)

SENSING_TACTILE = Topic(
    "sensing/tactile", Tactile, history=2, buffer=16, max_publishers=2, max_subscribers=16
)

SENSING_ODOM = Topic(
    "sensing/odom", Odom, history=1, buffer=16, max_publishers=2, max_subscribers=16
)

SENSING_BEACONS = Topic(
    "sensing/beacons", Beacons, history=1, buffer=16, max_publishers=2, max_subscribers=16
)

SENSING_FIX = Topic(
    "sensing/fix", Fix, history=1, buffer=16, max_publishers=2, max_subscribers=16
)

LOCALIZATION_POSE = Topic(
    "localization/pose", Pose, history=2, buffer=64, max_publishers=2, max_subscribers=16
)

LOCALIZATION_PARTICLES = Topic(
    "localization/particles", Particles, history=0, buffer=2, max_publishers=2, max_subscribers=16
)

LOCALIZATION_LANDMARKS = Topic(
    "localization/landmarks", Landmarks, history=0, buffer=4, max_publishers=2, max_subscribers=16
)

LOCALIZATION_TRAJECTORY = Topic(
    "localization/trajectory", Trajectory, history=0, buffer=2, max_publishers=2, max_subscribers=16
)

MAPPING_GRID = Topic(
    "mapping/grid", Grid, history=1, buffer=4, max_publishers=2, max_subscribers=16
)

MAPPING_CONTACT = Topic(
    "mapping/contact", Grid, history=1, buffer=4, max_publishers=2, max_subscribers=16
)

PLANNING_CMD = Topic(
    "planning/cmd", Cmd, history=1, buffer=16, max_publishers=2, max_subscribers=16
)

PLANNING_STATUS = Topic(
    "planning/status", PlanStatus, history=0, buffer=4, max_publishers=2, max_subscribers=16
)

STACK_TICK = Topic(
    "stack/tick", Tick, history=0, buffer=16, max_publishers=2, max_subscribers=16
)

STACK_STATS = Topic(
    "stack/stats", Stats, history=0, buffer=64, max_publishers=32, max_subscribers=16
)

MONITOR_STATUS = Topic(
    "monitor/status", RunStatus, history=1, buffer=4, max_publishers=2, max_subscribers=16
)

STACK_PROCESSES = Topic(
    "stack/processes", Processes, history=1, buffer=4, max_publishers=2, max_subscribers=16
)

OPERATOR_GOAL = Topic(
    "operator/goal", Goal, history=1, buffer=16, max_publishers=2, max_subscribers=16
)

OPERATOR_PACE = Topic(
    "operator/pace", Pace, history=1, buffer=16, max_publishers=2, max_subscribers=16
)

STACK_FAULTS = Topic(
    "stack/faults", Fault, history=8, buffer=16, max_publishers=2, max_subscribers=64
)

STACK_PARAMS = Topic(
    "stack/params", ParamChange, history=8, buffer=16, max_publishers=32, max_subscribers=64
)

TOPICS = (
    WORLD_MAP, WORLD_TRUTH, SENSING_SCAN, SENSING_TACTILE, SENSING_ODOM, SENSING_BEACONS,
    SENSING_FIX, LOCALIZATION_POSE, LOCALIZATION_PARTICLES, LOCALIZATION_LANDMARKS,
    LOCALIZATION_TRAJECTORY, MAPPING_GRID, MAPPING_CONTACT, PLANNING_CMD, PLANNING_STATUS,
    STACK_TICK, STACK_STATS, MONITOR_STATUS, STACK_PROCESSES, OPERATOR_GOAL, OPERATOR_PACE,
    STACK_FAULTS, STACK_PARAMS,
)


def service_name(namespace: str, topic: str) -> str:
    """The iceoryx2 service name of a topic in a namespace."""
    return f"mole/{namespace}/{topic}"

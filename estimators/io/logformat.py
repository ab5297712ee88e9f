"""The sensor log: one Parquet file per stream in a run directory, columns documented and checked here.

This is the seam between the twin and the estimators (DESIGN "The sensor log"). Each stream is a table
whose columns carry their unit in the Parquet field metadata (key b"unit"). `read_stream` checks every
declared column is present with its unit and type, that no value is NaN where NaN is not allowed, that time is
strictly increasing (or non-decreasing for streams keyed by (t, id)) and that sensor values lie within their
physical limits (estimators.io.plausible); a problem, or a damaged file, raises `LogError` with one line naming
the file, the column and the first offending row, or how to get the file back.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from estimators.io.plausible import first_implausible


class LogError(ValueError):
    """A stream that cannot be used; the message names file, column and row."""


@dataclass(frozen=True)
class Column:
    name: str
    unit: str
    dtype: str  # "f8", "i8", "i4", "i1" or "str"
    doc: str
    nan_ok: bool = False


@dataclass(frozen=True)
class Stream:
    name: str
    doc: str
    columns: tuple[Column, ...]
    time_order: str = "increasing"  # "nondecreasing" for streams with a row per id per time; "none"

    @property
    def filename(self) -> str:
        return f"{self.name}.parquet"

    def column(self, name: str) -> Column:
        return next(c for c in self.columns if c.name == name)


NONORTH_AXES = ("xy", "xz", "yz")
"""The elements of the accelerometers' symmetric non-orthogonality A, in the filter's state order."""


def _xyz(prefix: str, unit: str, doc: str, axes: str | tuple[str, ...] = "xyz") -> tuple[Column, ...]:
    return tuple(Column(f"{prefix}_{a}", unit, "f8", f"{doc}, {a} component") for a in axes)


def _quat(prefix: str, doc: str) -> tuple[Column, ...]:
    return tuple(Column(f"{prefix}_{a}", "1", "f8", f"{doc}, {a} (scalar first, Hamilton)") for a in "wxyz")


T = Column("t", "s", "f8", "time from scenario start")

TRUTH_SHEARER = Stream(
    "truth_shearer",
    "True shearer body state at the ride rate. Body frame b: x towards the coal wall, y along the face "
    "towards the tailgate, z up; n is local-level ENU at the shearer; t is the ENU tangent plane at the "
    "scenario reference point (the MuJoCo world).",
    (
        T,
        Column("lat", "rad", "f8", "geodetic latitude (WGS-84)"),
        Column("lon", "rad", "f8", "geodetic longitude"),
        Column("h", "m", "f8", "ellipsoidal height"),
        *_xyz("p_t", "m", "position in the tangent plane t", "enu"),
        *_xyz("v_n", "m/s", "ground velocity in n", "enu"),
        *_quat("q_nb", "attitude, rotates b vectors into n"),
        *_xyz("w_ib_b", "rad/s", "inertial angular rate of b (what a perfect gyro reads)"),
        *_xyz("w_nb_b", "rad/s", "angular rate of b relative to n"),
        *_xyz("f_b", "m/s^2", "specific force in b (what a perfect accelerometer reads)"),
        Column("s", "m", "f8", "arc length of the body centre along the AFC running line from the headgate"),
        Column("pan_rear", "1", "i4", "pan under the headgate-side shoe"),
        Column("pan_front", "1", "i4", "pan under the tailgate-side shoe"),
        Column("cycle", "1", "i4", "cutting cycle"),
        Column("phase", "1", "i1", "haulage phase: 0 stopped, 1 cutting, 2 travel in cut coal, 3 sumping, "
                                   "4 cutting out the end"),
    ),
)

TRUTH_PANS = Stream(
    "truth_pans",
    "Every AFC pan's pose whenever it changes (initial state at t = 0, then after each push event). The "
    "pose is the centre of the pan's running line in t and its attitude q_tp. Bends are to the next pan "
    "(NaN for the last): horizontal = yaw difference, vertical = pitch difference of the pan Euler angles "
    "in the face frame (yaw about z, pitch about the advance axis, then roll).",
    (
        T,
        Column("pan", "1", "i4", "pan index from the headgate"),
        *_xyz("p_t", "m", "running-line centre in t", "enu"),
        *_quat("q_tp", "pan attitude in t"),
        Column("bend_h", "rad", "f8", "horizontal bend to the next pan", nan_ok=True),
        Column("bend_v", "rad", "f8", "vertical bend to the next pan", nan_ok=True),
        Column("advance", "m", "f8", "displacement towards the coal wall since t = 0"),
    ),
    time_order="nondecreasing",
)

TRUTH_SUPPORTS = Stream(
    "truth_supports",
    "Every hydraulic support's state whenever it changes: through every ram stroke and lowering and setting of its "
    "legs (sampled in real time), and as the roof converges on it.",
    (
        T,
        Column("support", "1", "i4", "support index from the headgate"),
        *_xyz("p_t", "m", "base reference point in t", "enu"),
        Column("advance", "m", "f8", "displacement towards the coal wall since t = 0"),
        Column("ram", "m", "f8", "push-ram length (tendon length between support and pan)"),
        Column("ram_pressure", "MPa", "f8", "pressure in the push ram's loaded side (annulus pushing, bore pulling)"),
        Column("canopy", "m", "f8", "canopy height above the base (its leg joint)"),
        Column("leg_pressure", "MPa", "f8", "pressure in the legs"),
        Column("set", "1", "i1", "1 when set against the roof, 0 from the legs' lowering to their set"),
    ),
    time_order="nondecreasing",
)

TRUTH_CYCLES = Stream(
    "truth_cycles",
    "Cutting-cycle boundaries and the closed-path corner points (001 Fig. 3): each cycle is a straight cut "
    "from one face end to the other, then snake sumping at that end (reverse into the snake, stop while the "
    "end pans are pushed, cut out to the face end).",
    (
        Column("cycle", "1", "i4", "cutting cycle"),
        Column("direction", "1", "i1", "+1 headgate to tailgate, -1 back"),
        Column("t", "s", "f8", "start of the straight cut"),
        Column("t_cut_end", "s", "f8", "shearer reaches the far end (point B of 001 Fig. 3)"),
        Column("t_sump_end", "s", "f8", "shearer has reversed into the snake (point C)"),
        Column("t_push_end", "s", "f8", "end pans pushed (point D)"),
        Column("t_end", "s", "f8", "shearer back at the far face end (point E), start of the next cycle"),
        Column("s_sump", "m", "f8", "arc length of the sump point C"),
    ),
)

IMU = Stream(
    "imu",
    "Shearer IMU increments over (t - Ts, t] in the IMU sensor frame s (nominally b; the mounting "
    "misalignment and lever arm are part of the sensor, not of this log).",
    (T, *_xyz("dtheta", "rad", "angle increment"), *_xyz("dv", "m/s", "velocity increment")),
)

ODOMETER = Stream(
    "odometer",
    "Haulage encoder: cumulative travelled distance (pulses times the nominal metres per pulse, signed by "
    "the direction of travel) and the pulse count.",
    (
        T,
        Column("distance", "m", "f8", "cumulative signed distance from the start (nominal scale)"),
        Column("pulses", "1", "i8", "cumulative signed pulse count"),
        Column("direction", "1", "i1", "+1 towards the tailgate, -1 towards the headgate, 0 standing"),
    ),
)

PUSHRAM = Stream(
    "pushram",
    "Push-ram stroke sensors, one row per support per sample; invalid readings are flagged, not dropped.",
    (
        T,
        Column("support", "1", "i4", "support index from the headgate"),
        Column("extension", "m", "f8", "ram length reading", nan_ok=True),
        Column("valid", "1", "i1", "1 when the sensor reports a reading, 0 on dropout"),
    ),
    time_order="nondecreasing",
)

PRESSURE = Stream(
    "pressure",
    "Pressure transducers of the supports' legs and push rams, one row per support per sample; invalid readings are "
    "flagged, not dropped.",
    (
        T,
        Column("support", "1", "i4", "support index from the headgate"),
        Column("leg", "MPa", "f8", "legs' pressure reading", nan_ok=True),
        Column("ram", "MPa", "f8", "push ram's pressure reading (its loaded side)", nan_ok=True),
        Column("valid_leg", "1", "i1", "1 when the leg transducer reports a reading, 0 on dropout"),
        Column("valid_ram", "1", "i1", "1 when the ram transducer reports a reading, 0 on dropout"),
    ),
    time_order="nondecreasing",
)

MAG = Stream(
    "mag",
    "Shearer magnetometer: the field in the body frame b (Earth field, hard and soft iron, motor field, "
    "interference, noise).",
    (T, *_xyz("b", "T", "magnetic flux density in b")),
)

SUPPORT_IMU = Stream(
    "support_imu",
    "9-axis units on support canopies, one row per unit per sample, in the canopy frame (x towards the coal "
    "wall, y along the face, z up).",
    (
        T,
        Column("support", "1", "i4", "support index"),
        *_xyz("gyro", "rad/s", "angular rate"),
        *_xyz("accel", "m/s^2", "specific force"),
        *_xyz("mag", "T", "magnetic flux density"),
    ),
    time_order="nondecreasing",
)

FAULTS = Stream(
    "faults",
    "The injected fault schedule: ground truth for the detectors.",
    (
        Column("kind", "1", "str", "fault kind (twin.config.sensors.FaultKind)"),
        Column("target", "1", "i4", "support index, or -1 when the fault has no target"),
        Column("t_start", "s", "f8", "window start"),
        Column("t_end", "s", "f8", "window end"),
        Column("value", "1", "f8", "magnitude in the kind's unit (see twin.config.sensors.Fault)"),
    ),
    time_order="none",
)

ALIGNMENT = Stream(
    "alignment",
    "The roof support system's log of face alignment (OPC 40561 use case 4.2.6): the offset each support's push "
    "applied in each cycle (the scenario's, the API's and the face alignment system's together), the sequence number "
    "of the alignment system's set among them (0: none) and that set's one-sigma.",
    (
        T,
        Column("cycle", "1", "i4", "cutting cycle whose push applied the offset (t: its start)"),
        Column("support", "1", "i4", "support index"),
        Column("offset", "m", "f8", "offset added to the push, positive towards the coal wall"),
        Column("sd", "m", "f8", "one-sigma of the alignment system's offset (NaN: none or unknown)", nan_ok=True),
        Column("sequence", "1", "i4", "SequenceNumber of the alignment system's set applied (0: none)"),
    ),
    time_order="nondecreasing",
)

SURVEY = Stream(
    "survey",
    "Surveyed fixes of the shearer body reference point (the truth's point): the start pose before the first "
    "cut and the face-end points (001 section 2.2: the ends of the face are measured in advance). Heading is "
    "NaN where the survey gives none.",
    (
        T,
        Column("lat", "rad", "f8", "geodetic latitude (WGS-84)"),
        Column("lon", "rad", "f8", "geodetic longitude"),
        Column("h", "m", "f8", "ellipsoidal height"),
        Column("yaw", "rad", "f8", "body yaw (DESIGN convention: counter-clockwise from north)", nan_ok=True),
        Column("sd_horizontal", "m", "f8", "one-sigma horizontal error of the fix"),
        Column("sd_vertical", "m", "f8", "one-sigma vertical error of the fix"),
        Column("sd_yaw", "rad", "f8", "one-sigma yaw error", nan_ok=True),
    ),
)

FACE_SURVEY = Stream(
    "face_survey",
    "The face line surveyed when the face is installed, before the first cut: where the shearer body reference "
    "point runs on the conveyor, one point per chute (the pan line surveyed and carried to the shearer's point "
    "with the machine geometry; 004's rail kinematics model of the first cut).",
    (
        T,
        Column("u", "m", "f8", "distance along the face from the start pose, the direction of the first cut"),
        Column("lat", "rad", "f8", "geodetic latitude (WGS-84)"),
        Column("lon", "rad", "f8", "geodetic longitude"),
        Column("h", "m", "f8", "ellipsoidal height"),
        Column("sd_horizontal", "m", "f8", "one-sigma horizontal error of the point"),
        Column("sd_vertical", "m", "f8", "one-sigma vertical error of the point"),
    ),
    time_order="nondecreasing",
)

MARKER = ".longwall-run"
"""The file that makes a directory a run directory (simulated or imported) `longwall run --force` may replace."""
MARKER_TEXT = "a longwall-twin run directory: `longwall run --force` may replace this directory\n"

# Bits of the estimates' `flags` column.
FLAG_VELOCITY = 1  # odometer / motion-constraint velocity update applied
FLAG_POSITION = 2  # position fix (CPOEM point or survey) applied
FLAG_ZUPT = 4  # zero-velocity update applied
FLAG_SKIPPED = 8  # a measurement was due but skipped (dropout, missing push-ram reading, gated)
FLAG_COVARIANCE_REPAIRED = 16  # the covariance was re-symmetrized / clipped to stay positive definite
FLAG_SMOOTHED = 32  # the row is an RTS-smoothed estimate
FLAG_MAG = 64  # magnetometer yaw update applied
FLAG_ISOLATED = 128  # the rail kinematics model is isolated (its fault detector holds a fault)
FLAG_UNHEALTHY = 256  # the health monitor found the filter lost track here (estimators.shearer.health)

ESTIMATE = Stream(
    "estimate",
    "One estimator's navigation solution for the shearer body reference point (the truth's point), written "
    "to estimates/NAME.parquet. One-sigma columns are NaN for methods without a covariance.",
    (
        T,
        Column("lat", "rad", "f8", "geodetic latitude (WGS-84)"),
        Column("lon", "rad", "f8", "geodetic longitude"),
        Column("h", "m", "f8", "ellipsoidal height"),
        *(Column(f"p_t_{a}", "m", "f8", f"position in the tangent plane t (as truth_shearer's p_t), {a}; NaN where "
                 "the run's reference point is unknown", nan_ok=True) for a in "enu"),
        *(Column(f"p_f_{a}", "m", "f8", f"position in the face frame F (x towards the coal wall, y along the face "
                 f"towards the tailgate, z up), {a}; NaN where the run's face is unknown", nan_ok=True) for a in "xyz"),
        *_xyz("v_n", "m/s", "ground velocity in n", "enu"),
        *_quat("q_nb", "attitude, rotates b vectors into n"),
        *(Column(f"sd_pos_{a}", "m", "f8", f"one-sigma position error, {a}", nan_ok=True) for a in "enu"),
        *(Column(f"sd_vel_{a}", "m/s", "f8", f"one-sigma velocity error, {a}", nan_ok=True) for a in "enu"),
        *(Column(f"sd_att_{a}", "rad", "f8", f"one-sigma attitude error angle about {a}", nan_ok=True)
          for a in "enu"),
        Column("flags", "1", "i4", "bitmask of estimators.io.logformat FLAG_* (what the step applied or skipped)"),
    ),
)

ESTIMATE_STATES = Stream(
    "estimate_states",
    "An error-state filter's sensor states (estimates/NAME_states.parquet): what it believes the sensor errors "
    "are, with one-sigma.",
    (
        T,
        *_xyz("gyro_bias", "rad/s", "gyro bias in b"),
        *_xyz("accel_bias", "m/s^2", "accelerometer bias in b"),
        *_xyz("odo_mount", "rad", "odometer mounting angle (001 eq. 10)"),
        Column("odo_scale", "1", "f8", "odometer scale-factor error delta k_D (001 eq. 1)"),
        *_xyz("accel_nonorth", "rad", "accelerometer non-orthogonality (symmetric A)", NONORTH_AXES),
        *_xyz("sd_gyro_bias", "rad/s", "one-sigma gyro bias"),
        *_xyz("sd_accel_bias", "m/s^2", "one-sigma accelerometer bias"),
        *_xyz("sd_odo_mount", "rad", "one-sigma odometer mounting angle"),
        Column("sd_odo_scale", "1", "f8", "one-sigma odometer scale-factor error"),
        *_xyz("sd_accel_nonorth", "rad", "one-sigma accelerometer non-orthogonality", NONORTH_AXES),
    ),
)

ESTIMATE_FUSION = Stream(
    "estimate_fusion",
    "A federated filter's fusion (estimates/NAME_fusion.parquet, 003 section 4, 004 section III): "
    "information-sharing coefficients, the magnetometer's estimated yaw noise and innovation, and each "
    "sub-filter's own estimate relative to the global one (NaN where the filter has no sub-filters). The aiding "
    "sub-filter is SINS/magnetometer (003) or SINS/rail kinematics model (004).",
    (
        T,
        Column("beta_odometer", "1", "f8", "information-sharing coefficient of the SINS/odometer sub-filter",
               nan_ok=True),
        Column("beta_aiding", "1", "f8", "information-sharing coefficient of the aiding sub-filter",
               nan_ok=True),
        Column("r_yaw", "rad^2", "f8", "yaw measurement noise variance used (estimated from the innovations)"),
        Column("yaw_innovation", "rad", "f8", "yaw closing-error innovation (NaN without a reading)", nan_ok=True),
        Column("mag_flags", "1", "i4", "bitmask of estimators.shearer.federated_filter MAG_* (read, disturbed, gated, used)"),
        *(Column(f"{sub}_d_pos_{a}", "m", "f8", f"{sub} sub-filter position minus the global one, {a}",
                 nan_ok=True) for sub in ("odometer", "aiding") for a in "enu"),
        *(Column(f"{sub}_d_yaw", "rad", "f8", f"{sub} sub-filter yaw minus the global one", nan_ok=True)
          for sub in ("odometer", "aiding")),
    ),
)

ESTIMATE_DETECTORS = Stream(
    "estimate_detectors",
    "The rail kinematics model's position fixes and the fault detectors on their innovations "
    "(estimates/NAME_detectors.parquet, 004 section IV), one row per fix.",
    (
        T,
        Column("lat", "rad", "f8", "predicted shearer body point on the rail: latitude"),
        Column("lon", "rad", "f8", "longitude"),
        Column("h", "m", "f8", "ellipsoidal height"),
        Column("residual", "1", "f8", "residual chi-square statistic of the fix's innovation (NaN: a surveyed face "
               "end, applied without the detectors)", nan_ok=True),
        Column("dual_state", "1", "f8", "dual-state chi-square statistic (with against without the fix)", nan_ok=True),
        Column("fsprt", "1", "f8", "fading sequential probability ratio statistic (004 eq. 23)", nan_ok=True),
        Column("applied", "1", "i4", "1 when the fix was applied, 0 when the isolating detector held a fault"),
        Column("isolated", "1", "i4", "1 while the rail kinematics model is isolated"),
    ),
)

ESTIMATE_SUPPORT_ATTITUDE = Stream(
    "estimate_support_attitude",
    "One method's canopy attitude for every instrumented support (estimates/METHOD_support_attitude.parquet, "
    "002_5cc0b59ad045ffaa.txt): one row per support per output sample, ordered like SUPPORT_IMU. Canopy frame c "
    "as in SUPPORT_IMU, n local-level ENU; Euler angles as DESIGN (C_c^n = Rz(yaw) Rx(pitch) Ry(roll)). Gyro bias "
    "and one-sigma are NaN for methods without them (002's KF and UKF).",
    (
        T,
        Column("support", "1", "i4", "support index"),
        *_quat("q_nc", "canopy attitude, rotates c vectors into n"),
        Column("pitch", "rad", "f8", "about the canopy x axis (towards the coal wall): the face's inclination"),
        Column("roll", "rad", "f8", "about the canopy y axis (along the face): the fore-aft tilt"),
        Column("yaw", "rad", "f8", "counter-clockwise from north"),
        *(Column(f"gyro_bias_{a}", "rad/s", "f8", f"estimated gyro bias in c, {a}", nan_ok=True) for a in "xyz"),
        *(Column(f"sd_att_{a}", "rad", "f8", f"one-sigma attitude error about c's {a} axis", nan_ok=True)
          for a in "xyz"),
        Column("flags", "1", "i4", "bitmask of estimators.support.error_state FLAG_* (0 for 002's filters)"),
    ),
    time_order="nondecreasing",
)

TRUTH_STREAMS = (TRUTH_SHEARER, TRUTH_PANS, TRUTH_SUPPORTS, TRUTH_CYCLES)
SENSOR_STREAMS = (IMU, ODOMETER, PUSHRAM, PRESSURE, MAG, SUPPORT_IMU, FAULTS, ALIGNMENT, SURVEY, FACE_SURVEY)
ESTIMATE_STREAMS = (ESTIMATE, ESTIMATE_STATES, ESTIMATE_FUSION, ESTIMATE_DETECTORS, ESTIMATE_SUPPORT_ATTITUDE)
STREAMS = {s.name: s for s in TRUTH_STREAMS + SENSOR_STREAMS}


def make_table(stream: Stream, data: dict[str, np.ndarray]) -> pa.Table:
    """Build a stream table from column arrays, in the declared order, units in the field metadata."""
    missing = [c.name for c in stream.columns if c.name not in data]
    if missing:
        raise LogError(f"{stream.name}: missing columns {', '.join(missing)}")
    fields, arrays = [], []
    for c in stream.columns:
        if c.dtype == "str":
            arrays.append(pa.array([str(v) for v in data[c.name]], pa.string()))
        else:
            arrays.append(pa.array(np.ascontiguousarray(data[c.name], dtype=np.dtype(c.dtype))))
        fields.append(pa.field(c.name, arrays[-1].type, metadata={b"unit": c.unit.encode()}))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields, metadata={b"stream": stream.name.encode()}))


ROW_GROUP_ROWS = 1 << 17
"""Rows per Parquet row group of a stream file (the last holds the rest): a file's bytes do not depend on the
blocks it was written in."""


def write_stream(run_dir: Path, stream: Stream, data: dict[str, np.ndarray] | pa.Table) -> Path:
    with StreamAppender(run_dir, stream) as appender:
        appender.append(data)
    return appender.path


class StreamAppender:
    """Writes a stream file block by block (a streaming run), in row groups of ROW_GROUP_ROWS: the same rows give the
    same bytes however they were split into blocks. Holds at most a row group's worth of rows; the file exists
    once the appender is closed (with the schema and no rows if nothing was appended)."""

    def __init__(self, run_dir: Path, stream: Stream):
        self.stream, self.path = stream, Path(run_dir) / stream.filename
        self._writer: pq.ParquetWriter | None = None
        self._held: list[pa.Table] = []
        self._rows = 0
        self._schema: pa.Schema | None = None

    def append(self, data: dict[str, np.ndarray] | pa.Table) -> None:
        table = data if isinstance(data, pa.Table) else make_table(self.stream, data)
        self._schema = self._schema or table.schema
        if table.num_rows:
            self._held.append(table)
            self._rows += table.num_rows
        while self._rows >= ROW_GROUP_ROWS:
            self._flush(ROW_GROUP_ROWS)

    def close(self) -> None:
        if self._schema is None:
            self._schema = make_table(self.stream, {c.name: np.zeros(0) for c in self.stream.columns}).schema
        self._flush(self._rows)
        if self._writer is None:
            self._writer = stream_writer(self.path, self._schema)
        self._writer.close()

    def _flush(self, rows: int) -> None:
        if not rows:
            return
        held = pa.concat_tables(self._held)
        if self._writer is None:
            self._writer = stream_writer(self.path, self._schema)
        self._writer.write_table(held.slice(0, rows), row_group_size=rows)
        rest = held.slice(rows)
        self._held, self._rows = ([rest] if rest.num_rows else []), rest.num_rows

    def __enter__(self) -> StreamAppender:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def stream_writer(path: Path, schema: pa.Schema) -> pq.ParquetWriter:
    """A Parquet writer for a stream file: each `write_table` appends row groups (a log written in blocks)."""
    # Byte-stream split makes smooth float64 series compress about 40 % better than plain zstd.
    floats = [f.name for f in schema if pa.types.is_floating(f.type)]
    return pq.ParquetWriter(path, schema, compression="zstd", use_dictionary=False,
                            use_byte_stream_split=floats or False)


def check_table(stream: Stream, table: pa.Table, source: str, before: dict[str, float] | None = None,
                first_row: int = 0) -> None:
    """Raise LogError naming the first problem: missing column, wrong unit or type, NaN, time order, a value
    outside the physical limits of estimators.io.plausible. `before` holds the row before the table's first
    and `first_row` the file's row number of the table's first (a log checked in blocks)."""
    names = set(table.column_names)
    for c in stream.columns:
        if c.name not in names:
            raise LogError(f"{source}: missing column '{c.name}' ({c.doc} [{c.unit}])")
        meta = table.schema.field(c.name).metadata or {}
        unit = meta.get(b"unit", b"").decode()
        if unit != c.unit:
            raise LogError(f"{source}: column '{c.name}' has unit '{unit or '(none)'}', expected '{c.unit}'")
        kind = table.schema.field(c.name).type
        if kind != (pa.string() if c.dtype == "str" else pa.from_numpy_dtype(np.dtype(c.dtype))):
            raise LogError(f"{source}: column '{c.name}' has type {kind}, expected {c.dtype} ({c.doc})")
        values = table.column(c.name).to_numpy(zero_copy_only=False)
        if values.dtype.kind == "f" and not c.nan_ok:
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise LogError(f"{source}: column '{c.name}' row {first_row + bad[0]}: not a finite number")
    t = table.column("t").to_numpy() if "t" in names and stream.time_order != "none" else None
    row0 = first_row + 1  # the table row of dt[0]'s later end
    if t is not None and before is not None and "t" in before:
        t = np.concatenate(([before["t"]], t))
        row0 -= 1
    if t is not None and t.size > 1:
        dt = np.diff(t)
        bad = np.flatnonzero(dt <= 0 if stream.time_order == "increasing" else dt < 0)
        if bad.size:
            raise LogError(f"{source}: column 't' row {row0 + bad[0]}: time goes from {t[bad[0]]!r} to "
                           f"{t[bad[0] + 1]!r} (must be {stream.time_order})")
    found = first_implausible(stream.name, table, before)
    if found is not None:
        row, column, what = found
        raise LogError(f"{source}: column '{column}' row {first_row + row}: {what}")


def read_stream(run_dir: Path, stream: Stream, columns: tuple[str, ...] | None = None) -> pa.Table:
    """The stream's file in run_dir, checked (check_table); only `columns` (declared names) when given."""
    path = Path(run_dir) / stream.filename
    if not path.is_file():
        raise LogError(f"{path}: stream file not found")
    if columns is not None:
        stream = Stream(stream.name, stream.doc, tuple(c for c in stream.columns if c.name in columns),
                        stream.time_order)
    try:
        table = pq.read_table(path, columns=None if columns is None else [c.name for c in stream.columns])
    except (pa.ArrowException, OSError, ValueError) as err:
        raise LogError(f"{path}: not a readable Parquet file ({' '.join(str(err).split())}); {_remedy(path)}") from None
    check_table(stream, table, str(path))
    return table


class StreamBlocks:
    """A stream's file in run_dir read a row group at a time (only `columns`, declared names, when given): each
    iteration reads the file again, each block checked as read_stream checks a whole file (check_table, with the row
    before it and its row numbers in the file). For a consumer that needs a long stream once or twice, not whole."""

    def __init__(self, run_dir: Path, stream: Stream, columns: tuple[str, ...] | None = None):
        self.path, self.stream = Path(run_dir) / stream.filename, stream
        if columns is not None:
            self.stream = Stream(stream.name, stream.doc, tuple(c for c in stream.columns if c.name in columns),
                                 stream.time_order)
        read_schema(self.path)  # a damaged file: one line with the remedy

    def __iter__(self) -> Iterator[pa.Table]:
        parquet = pq.ParquetFile(self.path)
        names = [c.name for c in self.stream.columns]
        before, first_row = None, 0
        for g in range(parquet.num_row_groups):
            table = parquet.read_row_group(g, columns=[n for n in names if n in parquet.schema_arrow.names])
            check_table(self.stream, table, str(self.path), before, first_row)
            if table.num_rows:
                before = {n: table.column(n)[-1].as_py() for n in names}
            first_row += table.num_rows
            yield table
        if parquet.num_row_groups == 0:
            check_table(self.stream, parquet.schema_arrow.empty_table(), str(self.path))
            yield parquet.schema_arrow.empty_table()

    def column(self, name: str) -> np.ndarray:
        """One column over the whole file."""
        return np.concatenate([b.column(name).to_numpy() for b in StreamBlocks(self.path.parent, self.stream, (name,))])


def read_schema(path: Path) -> pa.Schema:
    """The schema of a stream or estimate file, LogError when it is not a readable Parquet file."""
    try:
        return pq.read_schema(path)
    except (pa.ArrowException, OSError, ValueError) as err:
        raise LogError(f"{path}: not a readable Parquet file ({' '.join(str(err).split())}); {_remedy(path)}") from None


def _remedy(path: Path) -> str:
    """How to get a damaged file of a run directory back."""
    if path.parent.name == ESTIMATES_DIR:
        return f"run `longwall estimate {path.parent.parent}` again to rewrite the estimates"
    return ("the run directory is damaged: import the recording again (`longwall import CSV_DIR --out NEW_DIR`) "
            "or run the scenario again")


ESTIMATES_DIR = "estimates"


_ESTIMATE_SUFFIX = {"estimate": "", "estimate_states": "_states", "estimate_fusion": "_fusion",
                    "estimate_detectors": "_detectors", "estimate_support_attitude": "_support_attitude"}


def estimate_path(run_dir: Path, method: str, stream: Stream = ESTIMATE) -> Path:
    """Where estimator `method` writes its solution (or its ESTIMATE_STATES, ESTIMATE_FUSION) in a run directory."""
    return Path(run_dir) / ESTIMATES_DIR / f"{method}{_ESTIMATE_SUFFIX[stream.name]}.parquet"


def estimate_file(run_dir: Path, method: str, stream: Stream = ESTIMATE) -> tuple[Path, Stream]:
    """The folder of estimator `method`'s `stream` file (estimate_path) and the stream named after the file (what
    write_stream, read_stream and StreamAppender take)."""
    path = estimate_path(run_dir, method, stream)
    return path.parent, Stream(path.stem, stream.doc, stream.columns, stream.time_order)


def write_estimate(run_dir: Path, method: str, data: dict[str, np.ndarray], stream: Stream = ESTIMATE) -> Path:
    folder, named = estimate_file(run_dir, method, stream)
    folder.mkdir(parents=True, exist_ok=True)
    return write_stream(folder, named, make_table(stream, data))


def read_estimate(run_dir: Path, method: str, stream: Stream = ESTIMATE) -> pa.Table:
    return read_stream(*estimate_file(run_dir, method, stream))

"""001's traditional method (section 4), the baseline of every table: the free SINS attitude carries the odometer
distance along body y, from the surveyed start. ``dr`` as it is; ``dr_compensated`` with the sensor biases, odometer
scale and mounting a filter estimated (kf_cpoem_rts's last row). Pass by pass (`DeadReckoningPasses`, as an online
run feeds it, estimators.shearer.online) or over a prepared log (`dead_reckoning`), the same rows bit for bit."""

from __future__ import annotations

import numpy as np

from estimators.io.log import Log
from estimators.kalman import error_state as es
from estimators.nav import earth
from estimators.nav.rotations import quat_rotate, quat_to_mat, rotvec_to_quat
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.prepare import Prepared
from estimators.shearer.solution import N_SD, Solution, join_rows, rows_of
from estimators.sins.strapdown import Mechanization


class DeadReckoningPasses:
    """001's traditional method pass by pass: the free SINS attitude carries the odometer distance along body y
    (with `cal`, the biases, odometer mounting and scale of a filter are applied first), the SINS and the position
    carried from pass to pass. `run` gives a pass's rows as `dead_reckoning` of the whole log has them, bit for
    bit (the sums in the same order)."""

    def __init__(self, cfg: Config, prep: Prepared, body0_llh: np.ndarray, cal: np.ndarray | None = None):
        cal = np.zeros(es.N_CAL) if cal is None else cal
        self.gyro, self.accel, self.scale = cal[es.CAL_GYRO], cal[es.CAL_ACCEL], cal[es.CAL_SCALE]
        self.dt = 1.0 / (1.0 / prep.imu_dt)
        self.sins = Mechanization(prep.nav0[es.LAT], prep.nav0[es.LON], prep.nav0[es.HGT], np.zeros(3),
                                  prep.nav0[es.QUAT], cfg.n_samples)
        self.y_m_b = quat_to_mat(rotvec_to_quat(cal[es.CAL_MOUNT]))[:, 1]  # odometer axis in b (C_m^b: rotvec)
        self.body0 = body0_llh
        self.enu = np.zeros((1, 3))  # the body point at the last epoch run, in the tangent plane at body0
        self.notes: list[str] = []  # (dead reckoning has nothing to say of itself)

    def run(self, prep: Prepared, a: int, b: int) -> Solution:
        """Epochs a..b (row 0 at epoch a: at epoch 0 the start, at rest; else the previous pass's last)."""
        t, dtheta_b, dv_b, first_row = prep.epoch_increments(a, b)
        try:
            q_nb = self.sins.run(t, dtheta_b - self.gyro * self.dt, dv_b - self.accel * self.dt,
                                 first_row).q_nb[::prep.steps]
        except ValueError as err:
            raise PositioningError(f"imu: {err}") from None
        dd = np.diff(prep.odo[prep.span(a, b)]) / (1 + self.scale)
        step_n = quat_rotate(q_nb[:-1], np.broadcast_to(self.y_m_b, (dd.size, 3))) * dd[:, None]
        enu = np.cumsum(np.concatenate([self.enu, step_n]), axis=0)
        self.enu = enu[-1:]
        t_kf = prep.t_kf[prep.span(a, b)]
        v_n = np.concatenate([np.zeros((1, 3)), step_n / np.diff(t_kf)[:, None]])
        return Solution(t_kf, np.column_stack(earth.enu_to_lla(enu, *self.body0)), v_n, q_nb,
                        np.full((t_kf.size, N_SD), np.nan), np.zeros(t_kf.size, np.int32))

    def finish(self, prep: Prepared) -> list[str]:
        return self.notes


def dead_reckoning(log: Log, cfg: Config, prep: Prepared, cal: np.ndarray | None = None) -> Solution:
    """001's traditional method over a prepared log (DeadReckoningPasses over its passes)."""
    passes = DeadReckoningPasses(cfg, prep, log.survey_llh[0], cal)
    rows = [passes.run(prep, a, b) for a, b in prep.segments]
    return join_rows([rows[0]] + [rows_of(r, slice(1, None)) for r in rows[1:]])

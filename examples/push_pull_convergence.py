"""Push-pull (poster): glue state and ungluing time against the exact gluey limit, for several dt.

Run: .venv/bin/python examples/push_pull_convergence.py (about 25 s; 50 s with ``solver="clarabel"``)
Prints gamma at the inversion, the ungluing time and the error of the free flight
``q(t) = (t - 4)^2 / 2`` after ungluing, which decreases like dt (first order). The steps are
solved by ``apgd-as`` (exact active-set finish: positions identical to Clarabel's here); the
gallery's ``push_pull_and_incline.py`` adds the incline and the convergence figure.
"""
import numpy as np

from lubcontact import GlueyLubrication, Simulation, scenes
from lubcontact.bench.tables import format_table


def run(dt: float, gamma_min=None) -> dict:
    sim = Simulation(scenes.push_pull(), GlueyLubrication(gamma_min=gamma_min), dt, d_max=0.02,
                     solver="apgd-as", tol=1e-10)
    gamma = []
    sim.run(int(round(5.0 / dt)), callback=lambda s, r: gamma.append(r.gamma.min() if r.gamma.size else 0.0))
    record = sim.trajectory.arrays()
    times, gap, gamma = record["times"][1:], record["positions"][1:, 0, 1] - 0.5, np.array(gamma)
    unglue = times[(gamma == 0) & (times > 2.0)][0]
    exact_unglue = 4.0 if gamma_min is None else 2.0 + abs(gamma_min)
    after = times >= exact_unglue
    flight_error = np.max(np.abs(gap[after] - 0.5 * (times[after] - exact_unglue) ** 2))
    return dict(dt=dt, gamma_min=str(gamma_min), gamma_at_2=gamma[int(round(2.0 / dt)) - 1],
                unglue_time=unglue, exact=exact_unglue, flight_error=flight_error)


if __name__ == "__main__":
    rows = [run(dt, gamma_min) for gamma_min in (None, -1.0) for dt in (1e-1, 1e-2, 1e-3)]
    print(format_table(rows, ["gamma_min", "dt", "gamma_at_2", "unglue_time", "exact", "flight_error"],
                       floats=".6g"))

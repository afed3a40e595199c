"""One time step taken apart: contacts, the step problem, and every registered solver on it.

Run: .venv/bin/python examples/anatomy_of_a_step.py (about 5 s)
"""
from lubcontact import GlueyLubrication, Simulation, methods, scenes
from lubcontact.bench.harness import compare_methods
from lubcontact.bench.tables import format_table

sim = Simulation(scenes.settling_pile(n_grains=300, seed=1), GlueyLubrication(), dt=0.05)
sim.run(80)
report = sim.step()
problem = report.problem
print(f"{report.contacts.count} contacts, {problem.n_dof} unknowns, W is "
      f"{problem.delassus.shape[0]}x{problem.delassus.shape[1]} with {problem.delassus.nnz} non-zeros")
print(f"cone kinds: {sorted(set(problem.cones.kinds.tolist()))} (0 unglued R+, 1 glued R)")
rows = compare_methods(problem, methods(), tol=1e-8)
print(format_table(rows, ["method", "status", "iterations", "setup_s", "solve_s", "velocity_error",
                          "residual", "min_gap"]))

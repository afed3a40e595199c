"""The demo's solver table reports solve times without one-time compilation."""
import os
import subprocess
import sys


def test_the_solver_table_times_exclude_numba_compilation(tmp_path):
    """In a fresh process with an empty numba cache, apgd (compiled kernel) and apgd-jacobi do the
    same work: their times must be comparable (compilation once made apgd 5.8 s against 0.007 s)."""
    script = ("from pathlib import Path; from lubcontact.demo import pile_section; "
              f"print(pile_section(Path({str(tmp_path)!r}), n_grains=60, steps=30))")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"), MPLBACKEND="Agg")
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         timeout=600, check=True).stdout
    rows = {line.split()[0]: line.split() for line in out.splitlines()
            if line.strip().startswith(("apgd ", "apgd-jacobi "))}
    header = next(line.split() for line in out.splitlines() if line.strip().startswith("method"))
    solve = header.index("solve_s")
    apgd, jacobi = float(rows["apgd"][solve]), float(rows["apgd-jacobi"][solve])
    assert rows["apgd"][1] == rows["apgd-jacobi"][1] == "converged"
    assert apgd <= 10 * jacobi + 0.01, (apgd, jacobi)


def test_the_pile_plot_separates_unglued_from_glued_contacts(tmp_path, monkeypatch):
    """Axes in grain diameters (the pile's unit), unglued contacts grey, glued ones on a log scale
    of |gamma| (a linear scale to gamma = -100 drew -5 < gamma < 0 in the unglued colour)."""
    from pathlib import Path

    import matplotlib.figure
    from matplotlib.colors import LogNorm

    from lubcontact.demo import pile_section

    figures = []
    monkeypatch.setattr(matplotlib.figure.Figure, "savefig",
                        lambda fig, *args, **kwargs: figures.append(fig))
    text = pile_section(Path(tmp_path), n_grains=60, steps=30)
    ax = figures[0].axes[0]
    assert ax.get_xlabel() == "x (grain diameters)" and ax.get_ylabel() == "y (grain diameters)"
    lines = [c for c in ax.collections if c.get_label().startswith("between grains")]
    unglued, glued = lines
    assert unglued.get_label().startswith("between grains, unglued (gamma = 0)")
    assert unglued.get_array() is None
    assert isinstance(glued.norm, LogNorm) and glued.get_array().min() > 0
    # the legend's counts are the report's contacts between grains (those with the walls not drawn)
    drawn = sum(int(line.get_label().rsplit(": ", 1)[1]) for line in lines)
    assert f"({drawn} between grains, " in text


def test_the_demo_names_the_methods_that_did_not_converge():
    """A row stopped at its cap is named under the table, not left for the reader to spot."""
    from lubcontact.bench.harness import MethodRow
    from lubcontact.demo import _unconverged_note

    rows = [MethodRow("apgd", "converged", 10, 0.0, 0.0, 0.0, 1e-14, 1e-14, 0.0),
            MethodRow("nsgs", "max_iter", 20000, 0.0, 0.0, 0.0, 5e-3, 1e-3, -4e-6)]
    note = _unconverged_note(rows)
    assert len(note) == 1 and note[0].startswith("Not converged on this step: nsgs (max_iter);")
    assert _unconverged_note(rows[:1]) == []

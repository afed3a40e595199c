"""Malformed problem files are refused with a ``ValueError`` naming the file and the field.

Targeted cases (truncated file, wrong counts, NaN, text where a number belongs,
non-square W, negative mu, wrong dimension, broken sparse listings, singular M)
for both formats, then seeded fuzzing: corruptions of the shipped files
(truncation, a number turned into ``nan`` or a word, a header count changed, a
line deleted or duplicated; for HDF5 a truncated file, a value made non-finite
or out of range, a member deleted, turned into text or shortened). Each must
raise ``ValueError`` (never ``IndexError``, ``KeyError``, ``TypeError`` or a
numpy/h5py error) whose message starts with the file's path.

Corruptions that leave a well-formed file are not errors and are not drawn:
deleting Siconos' optional second size line of a dense matrix or the optional
trailing integer, or (in a file that has that trailing integer) deleting a
one-number line, which shifts the integer into ``mu``; for HDF5, index changes
that stay in range, and ``nz = -1 <-> -2`` on a square ``W`` (its transpose).
"""
from __future__ import annotations

import re
import shutil

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

from lubcontact import io
from lubcontact.bench import problem_sets
from lubcontact.problem import LocalProblem

DATA = problem_sets.data_dir()
SEED = 20240611


def small_local(dim: int = 3) -> LocalProblem:
    rng = np.random.default_rng(0)
    a = rng.normal(size=(2 * dim, 2 * dim))
    return LocalProblem.from_contact_major(a @ a.T + np.eye(2 * dim), rng.normal(size=2 * dim),
                                           [0.3, 0.5], dim, name="small")


def small_global(dim: int = 3) -> io.GlobalProblem:
    rng = np.random.default_rng(1)
    return io.GlobalProblem(M=sp.diags(rng.uniform(1, 2, 5)), H=rng.normal(size=(5, 2 * dim)),
                            f=rng.normal(size=5), w=rng.normal(size=2 * dim), mu=[0.3, 0.5], dim=dim)


def refused(path, *fields: str) -> str:
    """Read ``path``: a ValueError starting with the path and naming every ``field``."""
    with pytest.raises(ValueError) as caught:
        io.read_problem(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: "), message
    for field in fields:
        assert re.search(rf"(?<![\w]){re.escape(field)}\b", message), (field, message)
    return message


# -- Siconos: targeted -----------------------------------------------------------------------------
def written(tmp_path, problem, storage, name="bad.dat") -> tuple:
    path = io.write_siconos(problem, tmp_path / name, storage=storage)
    return path, path.read_text().splitlines()


def edit(path, lines) -> None:
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("storage", [0, 1, 2])
def test_siconos_local_errors_name_file_and_field(tmp_path, storage):
    path, lines = written(tmp_path, small_local(), storage)
    q_line = len(lines) - 2
    cases = [
        (lines[: len(lines) // 2], ("W",)),                                   # truncated in W
        (lines[:-1], ("mu",)),                                                # truncated: no mu
        (["4"] + lines[1:], ("dim",)),                                        # wrong dimension
        (lines[:1] + ["3"] + lines[2:], ("W",)),                              # wrong contact count
        (lines[:3] + ["6", "5"] + lines[5:], ("W",)),                         # non-square W
        (lines[:q_line] + ["nan " + lines[q_line].split(" ", 1)[1]] + lines[-1:], ("q",)),
        (lines[:q_line] + ["abc " + lines[q_line].split(" ", 1)[1]] + lines[-1:], ("q",)),
        (lines[:-1] + ["0.3 -0.5"], ("mu",)),                                 # negative mu
        (lines[:-1] + ["0.3 inf"], ("mu",)),
        (lines + ["1.5"], ("mu",)),                                           # extra content
        (lines[:2] + ["7"] + lines[3:], ("W", "storage")),
        ([], ("dim",)),
    ]
    for content, fields in cases:
        edit(path, content)
        refused(path, *fields)


def test_siconos_matrix_listings_are_checked(tmp_path):
    path, lines = written(tmp_path, small_local(2), 2)
    header = next(k for k, line in enumerate(lines) if line.startswith("    col 1 "))
    cases = [
        (lines[:5] + ["4"] + lines[6:], ("W origin", "half-triplet")),
        (lines[:5] + ["1"] + lines[6:], ("W origin", "csc listing")),
        (lines[:7] + ["4-by-5, nzmax: 3 nnz: 3"] + lines[8:], ("W",)),       # size line vs header
        (lines[:6] + lines[7:], ("W", "CSparse size line")),                  # version line lost
        (lines[:header] + ["    col 2 : locations 2 to 3"] + lines[header + 1:], ("W",)),
        (lines[:header + 1] + ["      9 : 1.0"] + lines[header + 2:], ("W index",)),
        (lines[:header + 1] + ["      0 ; 1.0"] + lines[header + 2:], ("W",)),
    ]
    for content, fields in cases:
        edit(path, content)
        message = refused(path, *fields)
        assert "line" in message


def test_siconos_sparse_block_listing_is_checked(tmp_path):
    path, lines = written(tmp_path, small_local(3), 1)
    # lines: dim nc storage rows cols | nbblocks blocknumber0 blocknumber1 sizes0 sizes1 filled1 filled2
    #        index1 index2 | block 0 (number, 9 values) ...
    cases = [
        (lines[:8] + ["6\t3\t"] + lines[9:], ("W blocksize0",)),
        (lines[:12] + ["0\t2\t9\t"] + lines[13:], ("W index1_data",)),
        (lines[:13] + ["0\t7\t" + lines[13].split("\t", 2)[2]] + lines[14:], ("W index2_data",)),
        (lines[:14] + ["5"] + lines[15:], ("W block number",)),
        (lines[:11] + ["9"] + lines[12:], ("W filled2",)),
    ]
    for content, fields in cases:
        edit(path, content)
        refused(path, *fields)


@pytest.mark.parametrize("storage", [0, 2])
def test_siconos_global_errors_name_file_and_field(tmp_path, storage):
    record = small_global()
    path, lines = written(tmp_path, record, storage)
    h_line = next(k for k in range(5, len(lines)) if lines[k] == str(storage)
                  and lines[k + 1] == "5" and lines[k + 2] == "6")
    b_line = len(lines) - 2
    cases = [
        (lines[: h_line + 2] + ["7"] + lines[h_line + 3:], ("H",)),            # H has 7 columns
        (lines[: h_line + 1] + ["4"] + lines[h_line + 2:], ("H",)),            # rows of H != of M
        (lines[:b_line] + ["nan " + lines[b_line].split(" ", 1)[1]] + lines[-1:], ("b",)),
        (lines[:b_line - 1] + ["x " + lines[b_line - 1].split(" ", 1)[1]] + lines[b_line:], ("q",)),
        (lines[:-1] + ["-0.1 0.5"], ("mu",)),
        (lines[:3] + ["5", "4"] + lines[5:], ("W",)),                          # M not square
    ]
    for content, fields in cases:
        edit(path, content)
        refused(path, *fields)
    singular = io.GlobalProblem(M=sp.diags([1.0, 0.0, 1.0, 1.0, 1.0]), H=record.H, f=record.f,
                                w=record.w, mu=record.mu, dim=3)
    refused(io.write_siconos(singular, tmp_path / "singular.dat", storage=storage), "M", "singular")


def test_siconos_unreadable_or_missing_files(tmp_path):
    binary = tmp_path / "binary.dat"
    binary.write_bytes(b"\x89HDF\r\n\x1a\n\xff\xfe\x00")
    refused(binary)
    with pytest.raises(FileNotFoundError, match="absent"):
        io.read_problem(tmp_path / "absent.dat")
    with pytest.raises(ValueError, match="kind: must be 'local', 'global' or None"):
        io.read_siconos(io.write_siconos(small_local(), tmp_path / "ok.dat"), kind="both")


# -- FCLIB: targeted -------------------------------------------------------------------------------
def fclib_cases():
    def set_value(member, value, index=0):
        def change(handle):
            data = handle[member][()]
            data[index] = value
            handle[member][...] = data
        return change

    def replace(member, value):
        def change(handle):
            del handle[member]
            handle[member] = value
        return change

    def delete(member):
        def change(handle):
            del handle[member]
        return change

    return {
        "W/x nan": (set_value("fclib_local/W/x", np.nan), ("/fclib_local/W/x", "non-finite")),
        "q inf": (set_value("fclib_local/vectors/q", np.inf, 2), ("/fclib_local/vectors/q",)),
        "q text": (replace("fclib_local/vectors/q", np.bytes_(b"1 2 3")), ("/fclib_local/vectors/q",)),
        "q short": (replace("fclib_local/vectors/q", np.ones(5)), ("/fclib_local/vectors/q",)),
        "W missing": (delete("fclib_local/W"), ("/fclib_local/W", "missing")),
        "W/p missing": (delete("fclib_local/W/p"), ("/fclib_local/W/p", "missing")),
        "W non-square": (set_value("fclib_local/W/n", 5), ("/fclib_local/W/m, n",)),
        "W/p decreasing": (set_value("fclib_local/W/p", 99, 2), ("/fclib_local/W/p",)),
        "W/i out of range": (set_value("fclib_local/W/i", 6, 1), ("/fclib_local/W/i",)),
        "W/nz unknown": (set_value("fclib_local/W/nz", -3), ("/fclib_local/W/nz",)),
        "mu negative": (set_value("fclib_local/vectors/mu", -0.1), ("mu",)),
        "mu count": (replace("fclib_local/vectors/mu", np.ones(3)), ("/fclib_local/vectors/mu",)),
        "spacedim": (set_value("fclib_local/spacedim", 4), ("/fclib_local/spacedim",)),
        "spacedim 2": (set_value("fclib_local/spacedim", 2), ("mu",)),    # 6 rows = 3 contacts in 2D
        "vectors group": (replace("fclib_local/vectors", np.zeros(3)), ("/fclib_local/vectors/q",)),
        "no problem": (delete("fclib_local"), ("neither an fclib_local nor an fclib_global",)),
    }


@pytest.mark.parametrize("case", sorted(fclib_cases()))
def test_fclib_local_errors_name_file_and_field(tmp_path, case):
    change, fields = fclib_cases()[case]
    path = io.write_fclib_local(small_local(), tmp_path / "bad.hdf5")
    with h5py.File(path, "r+") as handle:
        change(handle)
    refused(path, *fields)


def test_fclib_global_errors_name_file_and_field(tmp_path):
    record = small_global()
    args = (record.M, record.H, record.f, record.w, record.mu)
    for member, value, fields in [("H/m", 4, ("/fclib_global/H/m, n",)),
                                  ("M/x", np.nan, ("/fclib_global/M/x",)),
                                  ("vectors/w", "short", ("/fclib_global/vectors/w",)),
                                  ("M/x", 0.0, ("M", "singular"))]:
        path = io.write_fclib_global(*args, tmp_path / "bad.hdf5")
        with h5py.File(path, "r+") as handle:
            data = handle[f"fclib_global/{member}"][()]
            if value == "short":
                del handle[f"fclib_global/{member}"]
                handle[f"fclib_global/{member}"] = data[:-1]
            else:
                data[0] = value
                handle[f"fclib_global/{member}"][...] = data
        refused(path, *fields)
    path = io.write_fclib_global(*args, tmp_path / "g.hdf5")
    with h5py.File(path, "r+") as handle:
        handle["fclib_global/G/m"] = [5]
    refused(path, "/fclib_global/G", "not supported")
    with pytest.raises(ValueError, match=r"local\.hdf5: a local problem"):
        io.read_global(io.write_fclib_local(small_local(), tmp_path / "local.hdf5"))


def test_fclib_not_hdf5(tmp_path):
    path = tmp_path / "text.hdf5"
    path.write_text("3\n1\n")
    assert "not a readable HDF5 file" in refused(path)


# -- fuzzing the shipped files -----------------------------------------------------------------------
SICONOS_FUZZ = ["siconos-testdata/FC3D_Example1.dat", "siconos-testdata/FC3D_Example1_SBM.dat",
                "siconos-testdata/FrictionContact3D_1c.dat",
                "siconos-testdata/FrictionContactProblem00031.dat",
                "siconos-testdata/GFC3D_Example1.dat", "siconos-testdata/GFC3D_TwoRods1.dat",
                "siconos-testdata/gfc2d_granularflowonwall_00069_00350.dat",
                "siconos-fc2d/fc2d_granularflowonwall_00667_00000.dat",
                "siconos-testdata/OneObject-i1028-138.hdf5.dat",
                "siconos-testdata/FC2D_SliderCrankLagrangian00000.dat",
                "siconos-testdata/Confeti-ex03-Fc3D-SBM.dat", "siconos-testdata/GFC3D_Example00.dat"]
SICONOS_OPS = ("truncate", "flip", "header", "delete", "duplicate")
FLOAT = re.compile(r"[-+]?(\d+\.\d*|\.\d+)([eE][-+]?\d+)?\Z")
LISTING_WORDS = ("CSparse", "nzmax", "col", "row")


def corrupt_text(text: str, op: str, rng: np.random.Generator) -> str:
    lines = text.splitlines(keepends=True)
    nonblank = [k for k, line in enumerate(lines) if line.strip()]
    if op == "truncate":                                  # anywhere before the mu line
        mu_line = max(k for k in nonblank if "." in lines[k])
        return text[: int(rng.integers(0, sum(len(line) for line in lines[:mu_line])))]
    if op == "flip":                                      # a number of the data -> nan, inf, a word
        spots = [(k, match) for k, line in enumerate(lines)
                 if not any(word in line for word in LISTING_WORDS)
                 for match in re.finditer(r"\S+", line) if FLOAT.match(match.group())]
        k, match = spots[rng.integers(len(spots))]
        word = ["nan", "NaN", "inf", "-inf", "abc", "1.2.3", "0x1p3", "--1"][rng.integers(8)]
        lines[k] = lines[k][: match.start()] + word + lines[k][match.end():]
        return "".join(lines)
    if op == "header":                                    # dim, nc, storage, rows or columns +- 1
        match = list(re.finditer(r"\S+", text))[rng.integers(5)]
        return text[: match.start()] + str(int(match.group()) + int(rng.choice([-1, 1]))) \
            + text[match.end():]
    if op == "delete":                                    # not a line whose loss leaves a valid file
        trailing = bool(re.fullmatch(r"\s*[0-9]+\s*", lines[nonblank[-1]]))
        nonblank = [k for k in nonblank if not (trailing and k == nonblank[-1])
                    and not re.fullmatch(r"[0-9]+\t[0-9]+\s*", lines[k])
                    and not (trailing and len(lines[k].split()) == 1)]
    k = nonblank[rng.integers(len(nonblank))]
    if op == "delete":
        del lines[k]
    else:
        lines.insert(k, lines[k])
    return "".join(lines)


def siconos_corruptions():
    rng = np.random.default_rng(SEED)
    out = []
    for round_ in range(5):
        for k, name in enumerate(SICONOS_FUZZ):
            op = SICONOS_OPS[(k + round_) % len(SICONOS_OPS)]
            out.append((name, op, int(rng.integers(2**31))))
    return out


@pytest.mark.parametrize("name, op, seed", siconos_corruptions())
def test_corrupted_siconos_files_are_refused(tmp_path, name, op, seed):
    text = (DATA / name).read_text()
    bad = corrupt_text(text, op, np.random.default_rng(seed))
    assert bad != text
    path = tmp_path / f"corrupt-{op}.dat"
    path.write_text(bad)
    message = refused(path)
    assert "malformed Siconos file" not in message          # a named check caught it, not the net


FCLIB_FUZZ = ["fclib-local/LMGC_100_PR_PerioBox-i00361-60-03000.hdf5",
              "fclib-local/Box_Stacks-i0122-82-5.hdf5", "fclib-local/local_problem_test.hdf5",
              "siconos-testdata/spheres-in-a-box-98-i10000-256-10.hdf5"]
FCLIB_OPS = ("truncate", "value", "delete", "text", "short")
READ_MEMBERS = re.compile(r"fclib_(local|global)/(spacedim|vectors/(q|f|w|mu)|[WMH]/(m|n|nz|p|i|x))\Z")


def corrupt_hdf5(path, op: str, rng: np.random.Generator) -> None:
    if op == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: int(rng.integers(0, len(data)))])
        return
    with h5py.File(path, "r+") as handle:
        names = []
        handle.visititems(lambda name, obj: names.append(name) if READ_MEMBERS.match(name) else None)
        name = sorted(names)[rng.integers(len(names))]
        data = np.array(handle[name][()])
        if op == "value":
            k = rng.integers(data.size)
            data.flat[k] = [np.nan, np.inf, -np.inf][rng.integers(3)] if data.dtype.kind == "f" \
                else [-7, 2**30][rng.integers(2)]
            handle[name][...] = data
            return
        del handle[name]
        if op == "text":
            handle[name] = np.bytes_(b"not a number")
        elif op == "short":
            handle[name] = data[:-1]


def fclib_corruptions():
    rng = np.random.default_rng(SEED + 1)
    return [(name, op, int(rng.integers(2**31))) for op in FCLIB_OPS for name in FCLIB_FUZZ
            for _ in range(2 if op in ("value", "delete") else 1)]


@pytest.mark.parametrize("name, op, seed", fclib_corruptions())
def test_corrupted_fclib_files_are_refused(tmp_path, name, op, seed):
    path = tmp_path / f"corrupt-{op}.hdf5"
    shutil.copy(DATA / name, path)
    corrupt_hdf5(path, op, np.random.default_rng(seed))
    message = refused(path)
    assert "unreadable FCLIB content" not in message


def test_fuzz_counts():
    assert len(siconos_corruptions()) == 60 and len(fclib_corruptions()) == 28

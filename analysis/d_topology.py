"""Study d: the topology of throws in one cell (writeup 5.5).

The three red-sea throws (1.65, 3.9), (1.5, 4), (1.2, 4.4): outcomes,
ground-contact sequences, and whether they are topologically the same
(equal sequences), also modulo the cube's rotations. Then a grid of the red
sea grouped by contact sequence: how many distinct sequences the outcome-3
cell holds, into how many contact-sequence cells it splits, and the
canonical forms modulo the 24 rotations / 48 symmetries; a prefix tree of
the sequences in the cell.

    python analysis/d_topology.py [--quick] [--res N] [--out DIR]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import _common as C

NAME = "topology"
POINTS = ((1.65, 3.9), (1.5, 4.0), (1.2, 4.4))


def reference_sequences() -> dict:
    import csv

    for d in (C.REPO.parent / "shared" / "reference", C.REPO / "tests" / "data" / "reference"):
        p = Path(d) / "writeup_points.csv"
        if p.exists():
            with open(p, newline="") as f:
                return {(round(float(r["x"]), 6), round(float(r["y"]), 6)): r for r in csv.DictReader(f)}
    return {}


def simpson(counts: np.ndarray) -> float:
    """Probability that two throws drawn (without replacement) share the label."""
    n = counts.sum()
    return float((counts * (counts - 1)).sum() / (n * (n - 1))) if n > 1 else float("nan")


def prefix_codes(seqs: np.ndarray, kmax: int) -> list[np.ndarray]:
    """Integer class of every throw's first k contact sets, k = 1..kmax (equal code = equal prefix).

    Sequences shorter than k keep their whole sequence as the prefix (a sentinel pads them).
    """
    parts = [str(q).split("-") for q in seqs.ravel()]
    n = len(parts)
    width = max(len(p) for p in parts)
    mat = np.full((n, max(width, kmax)), -1, dtype=np.int64)  # -1: the sequence has ended
    for i, p in enumerate(parts):
        mat[i, : len(p)] = [int(x) for x in p]  # a set's text (ascending node digits) read as a number
    codes, cur = [], np.zeros(n, dtype=np.int64)
    for k in range(kmax):
        _, cur = np.unique(cur * 1_000_000_000 + mat[:, k], return_inverse=True)
        cur = cur.astype(np.int64).ravel()
        codes.append(cur.reshape(seqs.shape))
    return codes


def fast_components(codes: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, int]:
    """Connected regions of equal code (face neighbours) among the nodes in ``mask``; 0 outside.

    Same result as ``label_cells`` restricted to ``mask``, in one pass over the edges (label_cells
    loops over the labels, which is slow for tens of thousands of contact sequences).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.arange(codes.size).reshape(codes.shape)
    rows, cols = [], []
    for off in ((1, 0), (0, 1)):
        a = (slice(0, codes.shape[0] - off[0]), slice(0, codes.shape[1] - off[1]))
        b = (slice(off[0], None), slice(off[1], None))
        same = (codes[a] == codes[b]) & mask[a] & mask[b]
        rows.append(idx[a][same])
        cols.append(idx[b][same])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(codes.size, codes.size))
    _, lab = connected_components(graph, directed=False)
    lab = lab.reshape(codes.shape)
    out = np.zeros(codes.shape, dtype=np.int64)
    _, inv = np.unique(lab[mask], return_inverse=True)
    out[mask] = inv.ravel() + 1
    return out, int(inv.max() + 1) if mask.any() else 0


def main(argv=None) -> dict:
    args = C.parser(__doc__.splitlines()[0]).parse_args(argv)
    st = C.Study(NAME, args)
    import matplotlib.pyplot as plt

    from dicetrace.analysis import canonical_contact_sequence, label_cells
    from dicetrace.analysis.plot import plot_contact_tree, plot_outcome_map
    from dicetrace.ics import seed_slice
    from dicetrace.simulate import simulate

    ref = reference_sequences()
    throws = []
    for x, y in POINTS:
        r = simulate(seed_slice(x, y))
        seq = r.contact_sequence
        rr = ref.get((round(x, 6), round(y, 6)))
        throws.append({
            "x": x, "y": y, "outcome": r.outcome, "steps": r.steps, "t_settle_s": r.t_settle_s,
            "n_changes": r.n_contact_changes, "sequence": seq,
            "rotations": canonical_contact_sequence(seq, canonical="rotations"),
            "symmetries": canonical_contact_sequence(seq, canonical="symmetries"),
            "matches_program": (rr["contact_sequence"] == seq and int(rr["outcome"]) == r.outcome
                                and int(rr["steps"]) == r.steps) if rr else None,
        })
    pairs = []
    for a in range(3):
        for b in range(a + 1, 3):
            ta, tb = throws[a], throws[b]
            sa, sb = ta["sequence"].split("-"), tb["sequence"].split("-")
            common = 0
            for u, v in zip(sa, sb):
                if u != v:
                    break
                common += 1
            pairs.append({"a": f"({ta['x']}, {ta['y']})", "b": f"({tb['x']}, {tb['y']})",
                          "same": ta["sequence"] == tb["sequence"],
                          "same_rot": ta["rotations"] == tb["rotations"],
                          "same_sym": ta["symmetries"] == tb["symmetries"], "common_prefix": common})
    st.results["throws"] = throws
    st.results["pairs"] = pairs
    st.results["tables"]["throws"] = C.md_table(throws, [
        ("x", "x", ""), ("y", "y", ""), ("outcome", "outcome", "d"), ("steps", "steps", "d"),
        ("n_changes", "contact changes", "d"), ("sequence", "contact sequence", ""),
        ("matches_program", "= program", "")])
    st.results["tables"]["pairs"] = C.md_table(pairs, [
        ("a", "throw", ""), ("b", "throw", ""), ("same", "same sequence", ""),
        ("same_rot", "same mod rotations", ""), ("same_sym", "same mod symmetries", ""),
        ("common_prefix", "common prefix (sets)", "d")])
    fig = plot_contact_tree({t["sequence"]: 1 for t in throws},
                            title="Contact sequences of the three red-sea throws")
    st.save_fig(fig, "d_tree_three", caption="Prefix tree of the three writeup throws' contact sequences.")

    # ---- the red-sea grid grouped by contact sequence
    res = st.res(301, 41)
    s = st.sample("red-sea", res, sequences=True)
    g, seq = s.labels, s.sequences
    ax_x, ax_y = s.axes
    ids, n = label_cells(g)
    # the outcome-3 cell holding (1.5, 4.0) (nearest node), and where the other two throws lie
    def node(x, y):
        return int(np.argmin(np.abs(ax_x - x))), int(np.argmin(np.abs(ax_y - y)))

    cell_of = {p: int(ids[node(*p)]) for p in POINTS}
    label_of = {p: int(g[node(*p)]) for p in POINTS}
    cid = cell_of[(1.5, 4.0)]
    in_cell = ids == cid
    cell_seqs = seq[in_cell]
    uniq, counts = np.unique(cell_seqs.astype(str), return_counts=True)
    order = np.argsort(-counts)
    rot = {u: canonical_contact_sequence(u, canonical="rotations") for u in uniq}
    sym = {u: canonical_contact_sequence(u, canonical="symmetries") for u in uniq}
    n_rot = len(set(rot.values()))
    n_sym = len(set(sym.values()))
    rot_counts = {}
    for u, c in zip(uniq, counts):
        rot_counts[rot[u]] = rot_counts.get(rot[u], 0) + c
    # contact-sequence cells inside the outcome cell, and in the whole window
    kmax = int(max(len(str(q).split("-")) for q in seq.ravel()))
    codes = prefix_codes(seq, kmax)
    full = codes[-1]  # equal code <=> equal whole sequence
    seq_ids, n_seq_cells = fast_components(full, in_cell)
    sizes = np.bincount(seq_ids[in_cell])[1:]
    _, n_whole = fast_components(full, np.ones_like(in_cell))
    prefix_len = np.array([len(u.split("-")) for u in uniq])
    # how many leading sets all throws of the cell share
    parts = [u.split("-") for u in uniq]
    common = 0
    while all(len(p) > common for p in parts) and len({p[common] for p in parts}) == 1:
        common += 1
    cell = {
        "cell_id": cid, "label": int(g[in_cell][0]), "n_nodes": int(in_cell.sum()),
        "frac_of_window": float(in_cell.mean()),
        "points_in_cell": {f"({p[0]}, {p[1]})": cell_of[p] == cid for p in POINTS},
        "points_label": {f"({p[0]}, {p[1]})": label_of[p] for p in POINTS},
        "n_sequences": int(len(uniq)), "n_rotation_classes": n_rot, "n_symmetry_classes": n_sym,
        "largest_sequence_frac": float(counts.max() / counts.sum()),
        "largest_rotation_class_frac": float(max(rot_counts.values()) / counts.sum()),
        "simpson_same_sequence": simpson(counts),
        "simpson_same_rotation_class": simpson(np.array(list(rot_counts.values()))),
        "n_seq_cells": int(n_seq_cells), "n_seq_cells_ge10": int((sizes >= 10).sum()),
        "largest_seq_cell_frac_of_cell": float(sizes.max() / in_cell.sum()),
        "frac_nodes_in_singleton_seq_cells": float(sizes[sizes == 1].sum() / in_cell.sum()),
        "common_prefix_sets": common,
        "median_sequence_sets": float(np.median(np.repeat(prefix_len, counts))),
        "top_sequences": [{"sequence": str(uniq[i]), "count": int(counts[i])} for i in order[:8]],
    }
    # how the cell splits as more of the sequence is compared: distinct prefixes of k sets
    split_curve = []
    for k in range(1, min(40, kmax) + 1):
        ck = codes[k - 1]
        _, c = np.unique(ck[in_cell], return_counts=True)
        ids_k, n_k = fast_components(ck, in_cell)
        szk = np.bincount(ids_k[in_cell])[1:]
        split_curve.append({"k": k, "n_prefixes": int(len(c)), "largest_frac": float(c.max() / c.sum()),
                            "n_prefix_cells": n_k, "largest_prefix_cell_frac": float(szk.max() / in_cell.sum())})
    cell["split_curve"] = split_curve
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ks = [r["k"] for r in split_curve]
    ax.semilogy(ks, [r["n_prefixes"] for r in split_curve], "o-", ms=3, label="distinct prefixes")
    ax.semilogy(ks, [r["n_prefix_cells"] for r in split_curve], "s-", ms=3, label="connected prefix cells")
    ax.axhline(in_cell.sum(), color="0.5", ls=":", label="throws in the cell")
    ax.set_xlabel("k: contact sets compared (sequence prefix length)")
    ax.set_ylabel("count")
    ax.set_title("How the face-3 cell splits by contact-sequence prefix")
    ax.legend(fontsize=8)
    fig.tight_layout()
    st.save_fig(fig, "d_prefix_split", caption="Number of distinct contact-sequence prefixes of length k in the "
                "face-3 cell, and of the connected regions they form, against k.")
    window_stats = {
        "res": res, "n_nodes": int(g.size), "n_sequences": int(len(np.unique(seq.astype(str)))),
        "n_seq_cells": int(n_whole), "n_outcome_cells": int(n),
    }
    st.results["cell"] = cell
    st.results["window"] = window_stats
    st.log(f"cell {cid}: {cell['n_nodes']} nodes, {cell['n_sequences']} sequences, {n_rot} rotation classes, "
           f"{cell['n_seq_cells']} sequence cells")

    # figure: the outcome cell and its contact-sequence cells
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    plot_outcome_map(g, extent=s.extent, ax=axes[0], legend=False, title=f"red sea ({res}²): outcomes")
    for p in POINTS:
        axes[0].plot(*p, "wo", ms=5, mec="k")
    rng = np.random.default_rng(0)
    nid = seq_ids.max()
    cols = rng.uniform(0.15, 1.0, size=(nid + 1, 3))
    cols[0] = (0.85, 0.85, 0.85)
    img = cols[seq_ids]
    (x0, x1), (y0, y1) = s.extent
    axes[1].imshow(np.transpose(img, (1, 0, 2)), origin="lower", extent=(x0, x1, y0, y1), aspect="auto",
                   interpolation="nearest")
    for p in POINTS:
        axes[1].plot(*p, "wo", ms=5, mec="k")
    axes[1].set_title(f"the face-3 cell split by contact sequence ({cell['n_seq_cells']} cells)", fontsize=9)
    axes[1].set_xlabel("x")
    axes[1].set_ylabel("y")
    fig.tight_layout()
    st.save_fig(fig, "d_redsea_sequence_cells", caption="Left: outcomes of the red-sea window with the three "
                "throws (white dots). Right: the face-3 cell holding (1.5, 4) coloured by contact-sequence cell "
                "(random colours; grey outside the cell).")
    # tree of the sequences in the cell (first 8 sets; branches holding < 0.5 % of the cell hidden)
    depth = 8
    fig = plot_contact_tree({str(u): int(c) for u, c in zip(uniq, counts)}, max_depth=depth,
                            min_count=max(1, int(0.005 * counts.sum())),
                            title=f"Contact-sequence tree of the face-3 cell (first {depth} sets)")
    st.save_fig(fig, "d_tree_cell", caption=f"Prefix tree of the contact sequences in the face-3 cell (first "
                f"{depth} contact sets; edge width ~ log of the throws through it; branches with fewer than 0.5 % "
                "of the cell hidden).")
    st.results["tables"]["top_sequences"] = C.md_table(cell["top_sequences"], [
        ("sequence", "contact sequence", ""), ("count", "throws", "d")])
    st.results["res"] = res
    st.write()
    return st.results


if __name__ == "__main__":
    main(sys.argv[1:])

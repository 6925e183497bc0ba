"""Study d (topology): the topology of throws in one cell (writeup 5.5).

The three red-sea throws (1.65, 3.9), (1.5, 4), (1.2, 4.4): outcomes,
ground-contact sequences, and whether they are topologically the same
(equal sequences), also modulo the cube's rotations. Then a grid of the red
sea grouped by contact sequence: how many distinct sequences the outcome-3
cell holds, into how many contact-sequence cells it splits, and the
canonical forms modulo the 24 rotations / 48 symmetries; a prefix tree of
the sequences in the cell.
"""

from __future__ import annotations

import numpy as np

from dicetrace.analysis import canonical_contact_sequence, label_cells
from dicetrace.analysis.plot import plot_contact_tree, plot_outcome_map
from dicetrace.analysis.prefixes import fast_components, prefix_codes, simpson
from dicetrace.ics import TOPOLOGY_POINTS, seed_slice
from dicetrace.simulate import simulate
from dicetrace.studies.context import Computed, Context, Output
from dicetrace.studies.text import md_table

NAME = "topology"
#: The 2019 program's own run of the three throws (GNU Octave; rows 1-3 of
#: tests/data/reference/writeup_points.csv): (outcome, steps, contact sequence).
PROGRAM_THROWS = {
    (1.65, 3.9): (3, 540, "0-6-68-8-0-3-0-1-0-8-48-4-24-2-0-2-4-0-6-0-48-0-6"),
    (1.5, 4.0): (3, 552, "0-6-68-0-3-0-2-26-2-0-8-48-4-0-2-0-6-0-6-26-2-0-8-48-248-24"),
    (1.2, 4.4): (3, 479, "0-6-68-0-3-0-2-0-6-0-6-68-0-2-24-4-0-8"),
}
#: Contact sets shown in the tree of the cell's sequences.
TREE_DEPTH = 8


def three_throws() -> tuple[list[dict], list[dict]]:
    """The writeup's three throws (checked against the program) and their pairwise comparison."""
    throws = []
    for x, y in TOPOLOGY_POINTS:
        r = simulate(seed_slice(x, y))
        seq = r.contact_sequence
        prog = PROGRAM_THROWS.get((x, y))
        throws.append({
            "x": x, "y": y, "outcome": r.outcome, "steps": r.steps, "t_settle_s": r.t_settle_s,
            "n_changes": r.n_contact_changes, "sequence": seq,
            "rotations": canonical_contact_sequence(seq, canonical="rotations"),
            "symmetries": canonical_contact_sequence(seq, canonical="symmetries"),
            "matches_program": (prog == (r.outcome, r.steps, seq)) if prog else None,
        })
    pairs = []
    for a in range(len(throws)):
        for b in range(a + 1, len(throws)):
            ta, tb = throws[a], throws[b]
            common = 0
            for u, v in zip(ta["sequence"].split("-"), tb["sequence"].split("-")):
                if u != v:
                    break
                common += 1
            pairs.append({"a": f"({ta['x']}, {ta['y']})", "b": f"({tb['x']}, {tb['y']})",
                          "same": ta["sequence"] == tb["sequence"],
                          "same_rot": ta["rotations"] == tb["rotations"],
                          "same_sym": ta["symmetries"] == tb["symmetries"], "common_prefix": common})
    return throws, pairs


def compute(ctx: Context) -> Computed:
    throws, pairs = three_throws()
    # ---- the red-sea grid grouped by contact sequence
    res = ctx.res(301, 41)
    s = ctx.sample("red-sea", res, sequences=True)
    g, seq = s.labels, s.sequences
    ax_x, ax_y = s.axes
    ids, n = label_cells(g)

    def node(x, y):
        return int(np.argmin(np.abs(ax_x - x))), int(np.argmin(np.abs(ax_y - y)))

    # the outcome-3 cell holding (1.5, 4.0) (nearest node), and where the other two throws lie
    cell_of = {p: int(ids[node(*p)]) for p in TOPOLOGY_POINTS}
    label_of = {p: int(g[node(*p)]) for p in TOPOLOGY_POINTS}
    cid = cell_of[(1.5, 4.0)]
    in_cell = ids == cid
    uniq, counts = np.unique(seq[in_cell].astype(str), return_counts=True)
    order = np.argsort(-counts)
    rot = {u: canonical_contact_sequence(u, canonical="rotations") for u in uniq}
    sym = {u: canonical_contact_sequence(u, canonical="symmetries") for u in uniq}
    rot_counts: dict = {}
    for u, cnt in zip(uniq, counts):
        rot_counts[rot[u]] = rot_counts.get(rot[u], 0) + cnt
    # contact-sequence cells inside the outcome cell, and in the whole window
    kmax = int(max(len(str(q).split("-")) for q in seq.ravel()))
    codes = prefix_codes(seq, kmax)
    seq_ids, n_seq_cells = fast_components(codes[-1], in_cell)  # equal last code <=> equal whole sequence
    sizes = np.bincount(seq_ids[in_cell])[1:]
    _, n_whole = fast_components(codes[-1], np.ones_like(in_cell))
    prefix_len = np.array([len(u.split("-")) for u in uniq])
    # how many leading sets all throws of the cell share
    parts = [u.split("-") for u in uniq]
    common = 0
    while all(len(p) > common for p in parts) and len({p[common] for p in parts}) == 1:
        common += 1
    cell = {
        "cell_id": cid, "label": int(g[in_cell][0]), "n_nodes": int(in_cell.sum()),
        "frac_of_window": float(in_cell.mean()),
        "points_in_cell": {f"({p[0]}, {p[1]})": cell_of[p] == cid for p in TOPOLOGY_POINTS},
        "points_label": {f"({p[0]}, {p[1]})": label_of[p] for p in TOPOLOGY_POINTS},
        "n_sequences": int(len(uniq)), "n_rotation_classes": len(set(rot.values())),
        "n_symmetry_classes": len(set(sym.values())),
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
        _, cnt = np.unique(ck[in_cell], return_counts=True)
        ids_k, n_k = fast_components(ck, in_cell)
        szk = np.bincount(ids_k[in_cell])[1:]
        split_curve.append({"k": k, "n_prefixes": int(len(cnt)), "largest_frac": float(cnt.max() / cnt.sum()),
                            "n_prefix_cells": n_k, "largest_prefix_cell_frac": float(szk.max() / in_cell.sum())})
    cell["split_curve"] = split_curve
    window = {"res": res, "n_nodes": int(g.size), "n_sequences": int(len(np.unique(seq.astype(str)))),
              "n_seq_cells": int(n_whole), "n_outcome_cells": int(n)}
    ctx.log(f"cell {cid}: {cell['n_nodes']} nodes, {cell['n_sequences']} sequences, "
            f"{cell['n_rotation_classes']} rotation classes, {cell['n_seq_cells']} sequence cells")
    results = {"throws": throws, "pairs": pairs, "cell": cell, "window": window, "res": res}
    return Computed(results, {"sample": s, "seq_ids": seq_ids, "cell_sequences": dict(zip(map(str, uniq), counts))})


def render(c: Computed, out: Output) -> None:
    import matplotlib.pyplot as plt  # matplotlib is slow to import: only when drawing

    R = c.results
    out.tables["throws"] = md_table(R["throws"], [
        ("x", "x", ""), ("y", "y", ""), ("outcome", "outcome", "d"), ("steps", "steps", "d"),
        ("n_changes", "contact changes", "d"), ("sequence", "contact sequence", ""),
        ("matches_program", "= program", "")])
    out.tables["pairs"] = md_table(R["pairs"], [
        ("a", "throw", ""), ("b", "throw", ""), ("same", "same sequence", ""),
        ("same_rot", "same mod rotations", ""), ("same_sym", "same mod symmetries", ""),
        ("common_prefix", "common prefix (sets)", "d")])
    fig = plot_contact_tree({t["sequence"]: 1 for t in R["throws"]},
                            title="Contact sequences of the three red-sea throws")
    out.save_fig(fig, "d_tree_three", caption="Prefix tree of the three writeup throws' contact sequences.")
    cell, split_curve = R["cell"], R["cell"]["split_curve"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ks = [r["k"] for r in split_curve]
    ax.semilogy(ks, [r["n_prefixes"] for r in split_curve], "o-", ms=3, label="distinct prefixes")
    ax.semilogy(ks, [r["n_prefix_cells"] for r in split_curve], "s-", ms=3, label="connected prefix cells")
    ax.axhline(cell["n_nodes"], color="0.5", ls=":", label="throws in the cell")
    out.save_plot(fig, ax, "d_prefix_split", xlabel="k: contact sets compared (sequence prefix length)",
                  ylabel="count", title="How the face-3 cell splits by contact-sequence prefix", legend=8,
                  caption="Number of distinct contact-sequence prefixes of length k in the face-3 cell, and of the "
                  "connected regions they form, against k.")
    # the outcome cell and its contact-sequence cells
    s, seq_ids, res = c.plot["sample"], c.plot["seq_ids"], R["res"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    plot_outcome_map(s.labels, extent=s.extent, ax=axes[0], legend=False, title=f"red sea ({res}²): outcomes")
    cols = np.random.default_rng(0).uniform(0.15, 1.0, size=(seq_ids.max() + 1, 3))
    cols[0] = (0.85, 0.85, 0.85)
    (x0, x1), (y0, y1) = s.extent
    axes[1].imshow(np.transpose(cols[seq_ids], (1, 0, 2)), origin="lower", extent=(x0, x1, y0, y1), aspect="auto",
                   interpolation="nearest")
    for ax in axes:
        for p in TOPOLOGY_POINTS:
            ax.plot(*p, "wo", ms=5, mec="k")
    out.save_plot(fig, axes[1], "d_redsea_sequence_cells", xlabel="x", ylabel="y", legend=None, title_size=9,
                  title=f"the face-3 cell split by contact sequence ({cell['n_seq_cells']} cells)",
                  caption="Left: outcomes of the red-sea window with the three throws (white dots). Right: the "
                  "face-3 cell holding (1.5, 4) coloured by contact-sequence cell (random colours; grey outside "
                  "the cell).")
    counts = c.plot["cell_sequences"]
    total = sum(counts.values())
    fig = plot_contact_tree({u: int(n) for u, n in counts.items()}, max_depth=TREE_DEPTH,
                            min_count=max(1, int(0.005 * total)),
                            title=f"Contact-sequence tree of the face-3 cell (first {TREE_DEPTH} sets)")
    out.save_fig(fig, "d_tree_cell", caption=f"Prefix tree of the contact sequences in the face-3 cell (first "
                 f"{TREE_DEPTH} contact sets; edge width ~ log of the throws through it; branches with fewer than "
                 "0.5 % of the cell hidden).")
    out.tables["top_sequences"] = md_table(cell["top_sequences"], [
        ("sequence", "contact sequence", ""), ("count", "throws", "d")])

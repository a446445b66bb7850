#!/usr/bin/env python3
"""Write the skeleton inside the authors' fitted pymo pipeline (`motion_expmap_cr_scaled_20_data_pipe.sav`
or `motion_expmap_data_pipe.sav`, joblib) as a hierarchy-only BVH for `duolando generate --skeleton`.

    git -C /work/.mirror/guillefix+transflower-lightning/repo archive HEAD analysis/pymo | tar -x -C /tmp/tf
    /work/venv/bin/python tools/transflower_pipeline_skeleton.py --authors /tmp/tf \
        motion_expmap_cr_scaled_20_data_pipe.sav skeleton.bvh

The pickle names the authors' pymo classes, so their analysis/pymo must be importable (--authors: a
checkout or `git archive` of transflower-lightning; needs numpy, pandas, scipy, scikit-learn,
transforms3d, joblib). Read from the pipeline: JointSelector.orig_skeleton (the fit clip's whole
skeleton: offsets, channels, rotation orders), JointSelector.not_selected_values (what the inverse
puts in the channels it dropped: the fit clip's first frame) and Numpyfier's column names (the
feature layout, printed for a check against docs/TRANSFLOWER.md). `duolando` keeps the dropped joints
at their rest rotation: the script lists every dropped channel whose value is not 0.
"""
import argparse
import sys


def bvh_text(skel, root):
    lines = ["HIERARCHY"]

    def emit(name, depth):
        ind = "\t" * depth
        j = skel[name]
        o = j["offsets"]
        if name.endswith("_Nub"):
            lines.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}", f"{ind}}}"])
            return
        lines.append(f"{ind}{'ROOT' if j['parent'] is None else 'JOINT'} {name}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}\tOFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}")
        ch = j["channels"]
        if ch:
            lines.append(f"{ind}\tCHANNELS {len(ch)} {' '.join(ch)}")
        for c in j["children"]:
            emit(c, depth + 1)
        lines.append(f"{ind}}}")

    emit(root, 0)
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("pipeline", help="the authors' *_data_pipe.sav (joblib)")
    ap.add_argument("out", help="the BVH file to write (hierarchy only)")
    ap.add_argument("--authors", required=True, help="a checkout or archive of transflower-lightning (for analysis/pymo)")
    a = ap.parse_args()
    sys.path.insert(0, a.authors)
    import joblib

    pipe = joblib.load(a.pipeline)
    steps = dict(pipe.steps)
    jtsel = next((s for s in steps.values() if type(s).__name__ == "JointSelector"), None)
    if jtsel is None or not hasattr(jtsel, "orig_skeleton"):
        raise SystemExit(f"{a.pipeline}: no fitted JointSelector (steps: {', '.join(steps)})")
    skel = jtsel.orig_skeleton
    root = next(n for n, j in skel.items() if j["parent"] is None)
    with open(a.out, "w") as f:
        f.write(bvh_text(skel, root))
    joints = [n for n in skel if not n.endswith("_Nub")]
    print(f"wrote {a.out}: {len(joints)} joints, root {root}; kept by the pipeline: {', '.join(jtsel.selected_joints)}")
    npf = next((s for s in steps.values() if type(s).__name__ == "Numpyfier"), None)
    if npf is not None and hasattr(npf, "org_mocap_"):
        cols = list(npf.org_mocap_.values.columns)
        print(f"feature columns ({len(cols)}): {', '.join(cols)}")
    nonzero = {c: v for c, v in getattr(jtsel, "not_selected_values", {}).items() if float(v) != 0.0}
    if nonzero:
        print(f"dropped channels the authors' inverse fills with non-zero values ({len(nonzero)}; duolando uses the rest pose):")
        for c, v in nonzero.items():
            print(f"  {c} = {v}")
    else:
        print("every dropped channel is 0 in the pipeline: the rest pose, as duolando decodes it")


if __name__ == "__main__":
    main()

"""Free runs of a converted Transflower model through `duolando generate --noise` on held-out
dancers: the shared part of noise_check.py and s_vs_r.py."""
import os
import subprocess
import tempfile

import numpy as np

import train as T

HERE = os.path.dirname(os.path.abspath(__file__))
BIN = os.path.join(HERE, "..", "..", "..", "target", "release", "duolando")


class HeldOut:
    """The run's windows and modalities (its hparams.yaml) and 6 held-out dancers, spread over the
    test split, long enough for `steps` generated frames: `self.test` = [(name, motion_z, audio_z)]."""

    def __init__(self, hparams, prep, steps):
        import yaml
        hp = yaml.safe_load(open(hparams))
        self.lm, self.la = (int(x) for x in str(hp["input_lengths"]).split(","))
        self.h = int(hp.get("output_lengths", 3))
        self.mods = str(hp["input_modalities"]).split(",")
        self.steps = steps
        self.ms = T.read_scaler(os.path.join(prep, "motion_scaler.json"), T.MOTION_DIM)
        self.asc = T.read_scaler(os.path.join(prep, "audio_scaler.json"), T.AUDIO_DIM)
        test, _ = T.load_split(prep, "test", self.ms, self.asc, max(self.la, self.lm) + steps + 1)
        self.test = test[::max(1, len(test) // 6)][:6]
        self.work = tempfile.mkdtemp(prefix="tf_freerun_")

    def generate(self, bin_, model, motion, audio, noise, flags=()):
        """(steps, 69) frames from the dancer's first `lm` rows, its audio and these base samples."""
        w = self.work
        np.save(f"{w}/m.npy", motion[:self.lm].astype(np.float32))
        np.save(f"{w}/a.npy", audio[:self.la + self.steps - 1].astype(np.float32))
        np.save(f"{w}/z.npy", noise.astype(np.float32))
        subprocess.run([bin_, "generate", "--model", model, "--input", f"{self.mods[0]}={w}/m.npy",
                        "--input", f"{self.mods[1]}={w}/a.npy", "--noise", f"{w}/z.npy", "--out", f"{w}/o",
                        *flags], check=True, capture_output=True)
        return np.load(f"{w}/o/output.npy").reshape(self.steps, -1)

    def noise(self, rng):
        """One base sample per generated frame, (steps, 69, output_lengths)."""
        return rng.standard_normal((self.steps, T.MOTION_DIM, self.h))

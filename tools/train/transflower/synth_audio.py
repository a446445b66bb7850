"""Music for a `duolando synth` take, on the take's own beat grid (takes.json: bpm,
beats_per_bar, beats_s), so that audio features computed from it (the engine's
`duolando features --for transflower`) carry the rhythm the dancers move to.

    render_take(take, seconds, sr, seed) -> float32 mono samples in [-1, 1]

Deterministic: every random choice comes from numpy's PCG64 seeded with SHA-256 of
"<dataset seed>:<take name>". Per take: a random major key and one of the four
progressions the synth's own music features use (I-V-vi-IV, ii-V-I-vi, I-IV-V-IV, vi-IV-I-V),
one chord per bar; drum tuning and levels drawn around the genre's.

Every genre: kick on the downbeat (beat 0 of each bar), snare/clap on the other beats,
hi-hat between beats, a bass note on the chord root, a chord (sustained pad or per-beat
stabs). Per genre (the timbre and the pattern, loosely after the dance's music):

| genre | pad | hats | extra |
|---|---|---|---|
| Waltz | soft strings (sustained, vibrato), bass on 1 | quiet, straight | brushes on 2, 3 |
| Tango | reed (odd harmonics), staccato stabs on every beat | none | kick on every beat, snare drag before 1 |
| Foxtrot | organ (sustained), walking bass on every beat | swung | brushes |
| Quickstep | brass (bright), stabs on 2 and 4 | straight, loud | |
| Rumba | electric piano, bass on 1 and 3 | soft | 3-2 clave |
| ChaCha | electric piano stabs | straight | cowbell on beats, guiro on 4-and |
| Samba | brass, bass on 1 and 2 | 16th shaker | surdo accent on 2, agogo |
| Jive | piano stabs | swung (triplet) | claps on 2 and 4, boogie bass |
"""
import hashlib
import wave

import numpy as np

MAJOR = [0, 2, 4, 5, 7, 9, 11]
# degrees (0 = I) per bar, the four progressions of docs/SYNTH.md's music features
PROGRESSIONS = [[0, 4, 5, 3], [1, 4, 0, 5], [0, 3, 4, 3], [5, 3, 0, 4]]

GENRES = {
    # pad: harmonic rolloff exponent, odd-only, vibrato depth (semitones), level, sustained?
    "Waltz": dict(roll=1.6, odd=False, vib=0.08, pad=0.30, sustain=True, stab_beats=None,
                  hats=0.05, swing=0.5, sub=2, snare="brush", snare_lvl=0.35, kick_lvl=0.8,
                  kick_beats=None, bass="root", extra=None),
    "Tango": dict(roll=1.2, odd=True, vib=0.0, pad=0.35, sustain=False, stab_beats="all",
                  hats=0.0, swing=0.5, sub=2, snare="snap", snare_lvl=0.55, kick_lvl=1.0,
                  kick_beats="all", bass="beats", extra="drag"),
    "Foxtrot": dict(roll=1.0, odd=False, vib=0.03, pad=0.22, sustain=True, stab_beats=None,
                    hats=0.12, swing=0.66, sub=2, snare="brush", snare_lvl=0.45, kick_lvl=0.8,
                    kick_beats=None, bass="walk", extra=None),
    "Quickstep": dict(roll=0.9, odd=False, vib=0.0, pad=0.30, sustain=False, stab_beats=(1, 3),
                      hats=0.22, swing=0.5, sub=2, snare="snap", snare_lvl=0.7, kick_lvl=1.0,
                      kick_beats=None, bass="beats", extra=None),
    "Rumba": dict(roll=2.0, odd=False, vib=0.02, pad=0.30, sustain=True, stab_beats=None,
                  hats=0.07, swing=0.5, sub=2, snare="rim", snare_lvl=0.4, kick_lvl=0.9,
                  kick_beats=None, bass="one_three", extra="clave"),
    "ChaCha": dict(roll=2.0, odd=False, vib=0.0, pad=0.30, sustain=False, stab_beats="all",
                   hats=0.15, swing=0.5, sub=2, snare="rim", snare_lvl=0.5, kick_lvl=1.0,
                   kick_beats=None, bass="one_three", extra="cowbell"),
    "Samba": dict(roll=0.9, odd=False, vib=0.0, pad=0.22, sustain=True, stab_beats=None,
                  hats=0.10, swing=0.5, sub=4, snare="snap", snare_lvl=0.5, kick_lvl=1.0,
                  kick_beats=None, bass="beats", extra="samba"),
    "Jive": dict(roll=1.4, odd=False, vib=0.0, pad=0.30, sustain=False, stab_beats="all",
                 hats=0.18, swing=0.67, sub=2, snare="clap", snare_lvl=0.7, kick_lvl=1.0,
                 kick_beats=None, bass="boogie", extra=None),
}


def take_rng(seed, name):
    h = hashlib.sha256(f"{seed}:{name}".encode()).digest()
    return np.random.Generator(np.random.PCG64(int.from_bytes(h[:16], "little")))


def midi_hz(m):
    return 440.0 * 2.0 ** ((np.asarray(m, dtype=np.float64) - 69.0) / 12.0)


def chord_notes(key, degree):
    """Triad (root, third, fifth) as MIDI notes around C4 (60), root first."""
    notes = []
    for i in range(3):
        d = degree + 2 * i
        notes.append(60 + key + MAJOR[d % 7] + 12 * (d // 7))
    while notes[0] > 66:
        notes = [n - 12 for n in notes]
    return notes


class Mixer:
    def __init__(self, n, sr):
        self.y = np.zeros(n, dtype=np.float64)
        self.sr = sr

    def add(self, t0, x, gain=1.0):
        i = int(round(t0 * self.sr))
        if i >= len(self.y) or len(x) == 0:
            return
        if i < 0:
            x, i = x[-i:], 0
        m = min(len(x), len(self.y) - i)
        self.y[i:i + m] += gain * x[:m]


def onepole_hp(x, sr, fc):
    """One-pole high-pass (cheap, enough for noise colour)."""
    a = np.exp(-2 * np.pi * fc / sr)
    from scipy.signal import lfilter
    return lfilter([(1 + a) / 2, -(1 + a) / 2], [1, -a], x)


def onepole_lp(x, sr, fc):
    a = np.exp(-2 * np.pi * fc / sr)
    from scipy.signal import lfilter
    return lfilter([1 - a], [1, -a], x)


class Kit:
    """Drum sounds of one take (a few variants each, drawn once)."""

    def __init__(self, sr, rng):
        self.sr = sr
        self.rng = rng
        self.tune = rng.uniform(0.9, 1.1)
        self.cache = {}

    def _t(self, dur):
        return np.arange(int(dur * self.sr)) / self.sr

    def kick(self):
        if "kick" not in self.cache:
            t = self._t(0.45)
            f = 48 * self.tune + 110 * self.tune * np.exp(-t / 0.035)
            ph = 2 * np.pi * np.cumsum(f) / self.sr
            x = np.sin(ph) * np.exp(-t / 0.16)
            x += 0.3 * self.rng.standard_normal(len(t)) * np.exp(-t / 0.004)
            self.cache["kick"] = x
        return self.cache["kick"]

    def noise(self, dur, decay, lo, hi, key):
        if key not in self.cache:
            t = self._t(dur)
            n = self.rng.standard_normal(len(t))
            n = onepole_lp(onepole_hp(n, self.sr, lo), self.sr, hi)
            self.cache[key] = n / (np.abs(n).max() + 1e-9) * np.exp(-t / decay)
        return self.cache[key]

    def snare(self, kind):
        key = "snare_" + kind
        if key not in self.cache:
            t = self._t(0.3)
            if kind == "brush":
                x = self.noise(0.3, 0.09, 2000, 9000, "brushn") * 0.9
            elif kind == "rim":
                x = np.sin(2 * np.pi * 1700 * self.tune * t) * np.exp(-t / 0.015)
                x += 0.5 * self.noise(0.3, 0.01, 3000, 12000, "rimn")
            elif kind == "clap":
                x = np.zeros(len(t))
                base = self.noise(0.3, 0.07, 900, 6000, "clapn")
                for k, d in enumerate((0.0, 0.011, 0.023)):
                    i = int(d * self.sr)
                    x[i:] += base[: len(t) - i] * (0.7 if k < 2 else 1.0)
                x /= np.abs(x).max()
            else:  # snap
                x = 0.6 * np.sin(2 * np.pi * 190 * self.tune * t) * np.exp(-t / 0.05)
                x += self.noise(0.3, 0.06, 1500, 10000, "snapn")
            self.cache[key] = x
        return self.cache[key]

    def hat(self):
        return self.noise(0.12, 0.022, 7000, 16000, "hat")

    def shaker(self):
        return self.noise(0.08, 0.02, 5000, 12000, "shaker")

    def tone(self, hz, dur, decay, key):
        if key not in self.cache:
            t = self._t(dur)
            self.cache[key] = np.sin(2 * np.pi * hz * t) * np.exp(-t / decay)
        return self.cache[key]


def pad_tone(freqs, dur, sr, st, rng, stab=False):
    """Additive chord: harmonics 1..H with amplitude h^-roll (odd only for reed), two voices
    detuned by +-4 cents, vibrato; envelope sustained over `dur` or a short stab."""
    t = np.arange(int(dur * sr)) / sr
    y = np.zeros(len(t))
    hs = np.arange(1, 9)
    if st["odd"]:
        hs = hs[hs % 2 == 1]
    vib = st["vib"] * np.sin(2 * np.pi * 5.5 * t)
    for f in freqs:
        for det in (-4.0, 4.0):
            fr = f * 2.0 ** ((det / 100.0 + vib) / 12.0)
            ph = 2 * np.pi * np.cumsum(fr) / sr + rng.uniform(0, 2 * np.pi)
            for h in hs:
                if h * f > 0.45 * sr:
                    break
                y += np.sin(h * ph) * h ** (-st["roll"])
    if stab:
        env = np.minimum(t / 0.005, 1.0) * np.exp(-t / 0.12)
    else:
        a, r = 0.06, min(0.25, dur * 0.3)
        env = np.minimum(t / a, 1.0) * np.minimum(np.maximum(dur - t, 0.0) / r, 1.0)
    return y * env / (len(freqs) * 2 * 2.0)


def bass_tone(hz, dur, sr):
    t = np.arange(int(dur * sr)) / sr
    x = np.sin(2 * np.pi * hz * t) + 0.35 * np.sin(4 * np.pi * hz * t) + 0.1 * np.sin(6 * np.pi * hz * t)
    env = np.minimum(t / 0.008, 1.0) * np.exp(-t / max(0.15, 0.6 * dur))
    return x * env


def render_take(take, seconds, sr=48000, seed=0):
    """Mono float32 samples of `seconds` for one take of takes.json."""
    st = GENRES.get(take["genre"], GENRES["Foxtrot"])
    rng = take_rng(seed, take["name"])
    key = int(rng.integers(0, 12))
    prog = PROGRESSIONS[int(rng.integers(0, 4))]
    lv = {k: rng.uniform(0.8, 1.2) for k in ("kick", "snare", "hat", "pad", "bass", "extra")}
    kit = Kit(sr, rng)
    mix = Mixer(int(round(seconds * sr)), sr)
    period = 60.0 / float(take["bpm"])
    bpb = int(take["beats_per_bar"])
    beats = [float(b) for b in take["beats_s"]]
    if not beats:
        return mix.y.astype(np.float32)
    # extend the grid past the end so that the last bar's pad sounds to the end
    while beats[-1] < seconds + period:
        beats.append(beats[-1] + period)
    for b, tb in enumerate(beats):
        if tb >= seconds:
            break
        i, bar = b % bpb, b // bpb
        chord = chord_notes(key, prog[bar % 4])
        root_hz = midi_hz(chord[0] - 24)
        # drums
        if i == 0 or st["kick_beats"] == "all":
            mix.add(tb, kit.kick(), st["kick_lvl"] * lv["kick"] * (1.0 if i == 0 else 0.7))
        if i != 0:
            mix.add(tb, kit.snare(st["snare"]), st["snare_lvl"] * lv["snare"])
        if st["hats"] > 0:
            for s in range(1, st["sub"]):
                frac = st["swing"] if st["sub"] == 2 else s / st["sub"]
                snd = kit.hat() if st["sub"] == 2 else kit.shaker()
                mix.add(tb + frac * period, snd, st["hats"] * lv["hat"])
            if st["sub"] == 4:
                mix.add(tb, kit.shaker(), 0.6 * st["hats"] * lv["hat"])
        # chord
        if st["sustain"]:
            if i == 0:
                mix.add(tb, pad_tone(midi_hz(chord), bpb * period, sr, st, rng), st["pad"] * lv["pad"])
        else:
            sb = st["stab_beats"]
            if sb == "all" or (sb is not None and i in sb):
                mix.add(tb, pad_tone(midi_hz(chord), min(period, 0.5), sr, st, rng, stab=True),
                        st["pad"] * lv["pad"] * (1.2 if i == 0 else 1.0))
        # bass
        bass = st["bass"]
        if bass == "root" and i == 0:
            mix.add(tb, bass_tone(root_hz, bpb * period * 0.9, sr), 0.35 * lv["bass"])
        elif bass == "beats" or (bass == "one_three" and i in (0, 2)):
            mix.add(tb, bass_tone(root_hz * (1.5 if (bass == "beats" and i % 2 == 1) else 1.0), period * 0.9, sr), 0.3 * lv["bass"])
        elif bass == "walk":
            step = [0, 4, 7, 9][i % 4]
            mix.add(tb, bass_tone(midi_hz(chord[0] - 24 + step), period * 0.9, sr), 0.3 * lv["bass"])
        elif bass == "boogie":
            step = [0, 4, 7, 9][i % 4]
            for s, frac in ((0, 0.0), (1, st["swing"])):
                mix.add(tb + frac * period, bass_tone(midi_hz(chord[0] - 24 + step + 12 * s), period * 0.45, sr), 0.25 * lv["bass"])
        # genre extras
        ex = st["extra"]
        e = lv["extra"]
        if ex == "drag" and i == bpb - 1:
            for k in range(3):
                mix.add(tb + period * (0.5 + k / 6.0), kit.snare("snap"), 0.25 * e)
        elif ex == "clave":
            # 3-2 son clave over two bars of 4 (in eighths: 0, 3, 6 | 10, 12)
            pos = (bar % 2) * bpb * 2 + i * 2
            for eighth in (0, 3, 6, 10, 12):
                if pos <= eighth < pos + 2:
                    mix.add(tb + (eighth - pos) * period / 2, kit.tone(2500, 0.08, 0.015, "clave"), 0.4 * e)
        elif ex == "cowbell":
            mix.add(tb, kit.tone(800, 0.15, 0.05, "cowbell"), 0.25 * e)
            if i == bpb - 1:
                mix.add(tb + period / 2, kit.noise(0.15, 0.06, 3000, 9000, "guiro"), 0.3 * e)
        elif ex == "samba":
            if i == 1:
                mix.add(tb, kit.kick(), 0.9 * e)  # surdo accent on 2
            mix.add(tb + 0.75 * period, kit.tone(900 if i == 0 else 650, 0.12, 0.04, f"agogo{i % 2}"), 0.2 * e)
    # a faint noise floor (-60 dB) so that quiet passages are not digital silence
    y = mix.y + 1e-3 * rng.standard_normal(len(mix.y))
    peak = np.abs(y).max()
    if peak > 0:
        y *= 0.89 / peak
    return y.astype(np.float32)


def write_wav(path, y, sr):
    """16-bit PCM mono."""
    pcm = np.clip(np.round(y * 32767.0), -32768, 32767).astype("<i2")
    with wave.open(path, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(sr)
        w.writeframes(pcm.tobytes())

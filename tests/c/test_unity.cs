// Smoke test of the Unity wrapper (integrations/unity/Runtime/Duolando.cs) under
// Mono against libduolando.so: struct layouts, errors as exceptions, a
// session fed the fixture leader (with NaN glitches replaced by the last
// good frame) producing finite frames, converted to Unity coordinates; two
// sessions stepped through a StepBatch equal to each stepped alone; a solo
// (Bailando) model: info, presets, a SoloSession fed the golden music row
// by row (a NaN row refused on the way) and finished gives the golden
// positions within 1e-5 m, again after Reset with the rows as a track; the
// Duolando-only calls on it throw the library's message; positions pulled
// from a Duolando session equal its follower frames'.
// Built and run by .ci/ffi.sh when mcs/mono are present.
// usage: mono test_unity.exe <repo root>
using System;
using System.IO;
using System.Runtime.InteropServices;
using Duolando;

static class TestUnity
{
    static float[] ReadNpyF32(string path)
    {
        byte[] raw = File.ReadAllBytes(path);
        int header = 10 + raw[8] + 256 * raw[9];
        float[] data = new float[(raw.Length - header) / 4];
        Buffer.BlockCopy(raw, header, data, 0, data.Length * 4);
        return data;
    }

    static int failures = 0;

    static void Check(bool ok, string what)
    {
        if (!ok) { Console.Error.WriteLine("FAILED: " + what); failures++; }
    }

    static unsafe int Main(string[] args)
    {
        string root = args[0];
        Check(Marshal.SizeOf(typeof(LeaderFrame)) == 660, "LeaderFrame is 660 bytes");
        Check(Marshal.SizeOf(typeof(FollowerFrame)) == 1560, "FollowerFrame is 1560 bytes");
        Check(Marshal.SizeOf(typeof(SessionConfig)) == 64, "SessionConfig is 64 bytes");
        Check(Marshal.SizeOf(typeof(ModelInfo)) == 32, "ModelInfo is 32 bytes");
        Check(Model.Version == "0.2.0", "version");
        Check(Model.Threads == 1, "one thread by default");
        Model.Threads = 2;
        Check(Model.Threads == 2, "two threads");
        Model.Threads = 1;
        try { Model.Threads = 65; Check(false, "65 threads throws"); }
        catch (DuolandoException e) { Check(e.Result == DuoResult.InvalidArgument && e.Message.Contains("at most 64"), "InvalidArgument: " + e.Message); }
        try { Model.OpenFile("/nonexistent/model.duo"); Check(false, "missing file throws"); }
        catch (DuolandoException e) { Check(e.Result == DuoResult.Io && e.Message.Contains("/nonexistent/model.duo"), "Io with the path: " + e.Message); }
        try { Model.OpenCopy(new byte[100]); Check(false, "garbage throws"); }
        catch (DuolandoException e) { Check(e.Result == DuoResult.BadModel, "BadModel"); }

        float[] leader = ReadNpyF32(Path.Combine(root, "tests/fixtures/rollout_tiny_odd/leader_pos3d.npy"));
        float[] music = ReadNpyF32(Path.Combine(root, "tests/fixtures/rollout_tiny_odd/music.npy"));
        int frames = leader.Length / 165 / 4 * 4;
        float[] track = new float[frames * 54];
        Array.Copy(music, track, track.Length);

        int pulled = 0, rejected = 0;
        using (Model model = Model.OpenFile(Path.Combine(root, "tests/fixtures/tiny/model.duo")))
        {
            ModelInfo info = model.Info;
            Check(info.Joints == 55 && info.MusicFeatures == 54 && info.Mapped == 1, "info");
            SessionConfig config = model.MinimumConfig();
            // Softmax sampling: the temperature is the struct's last field
            // but one, so a C# layout that disagrees with the header's is refused.
            config.Sampling = SamplingMode.Softmax;
            config.TopK = 8;
            config.TemperatureMilli = 900;
            config.RngSeed = 3;
            uint[] seed = model.SeedTokens(SubArray(leader, 0, 8 * 165), SubArray(leader, 0, 8 * 165));
            using (Session session = new Session(model, config, seed))
            {
                // Without a track the latency is the live-music one (3 frames at the minimum budget).
                Check(session.LatencyFrames == 3, "latency 3 before the track");
                session.SetMusicTrack(track);
                Check(session.LatencyFrames == 0, "latency 0");
                LeaderFrame frame = new LeaderFrame();
                LeaderFrame lastGood = new LeaderFrame();
                FollowerFrame f = new FollowerFrame();
                for (int i = 0; i < frames; i++)
                {
                    for (int j = 0; j < 55; j++)
                        frame.Set(j, leader[i * 165 + 3 * j], leader[i * 165 + 3 * j + 1], leader[i * 165 + 3 * j + 2]);
                    if (i % 11 == 5) frame.Set(3, float.NaN, 0, 0);
                    DuoResult r = session.PushLeader(ref frame);
                    if (r == DuoResult.NonFiniteInput) { rejected++; r = session.PushLeader(ref lastGood); }
                    else if (r == DuoResult.Ok) lastGood = frame;
                    if (r == DuoResult.Backlog) break;
                    Check(r == DuoResult.Ok, "push " + i + ": " + r);
                    while (session.TryPull(ref f))
                    {
                        Check(f.Index == (ulong)pulled, "frame index");
                        Vec3 p = f.Position(0);
                        f.ConvertFromSmplX(Coords.Unity);
                        Vec3 u = f.Position(0);
                        Check(u.X == -p.X && u.Y == p.Y && u.Z == p.Z, "Unity conversion");
                        for (int j = 0; j < 55; j++)
                        {
                            Quat q = f.LocalRotation(j);
                            float n = q.X * q.X + q.Y * q.Y + q.Z * q.Z + q.W * q.W;
                            Check(!float.IsNaN(f.Position(j).X) && Math.Abs(n - 1) < 1e-4, "finite unit output");
                        }
                        pulled++;
                    }
                }
                session.Reset(seed);
            }
            // Two sessions (the second on the x-mirrored leader) stepped through a StepBatch
            // give the frames of the same sessions stepped alone, bit for bit.
            SessionConfig greedy = model.MinimumConfig();
            FollowerFrame[][] alone = new FollowerFrame[2][];
            for (int k = 0; k < 2; k++)
            {
                using (Session s = new Session(model, greedy, seed))
                {
                    s.SetMusicTrack(track);
                    var got = new System.Collections.Generic.List<FollowerFrame>();
                    FollowerFrame f = new FollowerFrame();
                    for (int i = 0; i < frames; i++)
                    {
                        LeaderFrame fr = FixtureFrame(leader, i, k == 1);
                        if (s.PushLeader(ref fr) == DuoResult.Backlog) break;
                        while (s.TryPull(ref f)) got.Add(f);
                    }
                    alone[k] = got.ToArray();
                }
            }
            // Session b is bound to the batch (duo_session_new_batched: no step memory of its own).
            using (StepBatch batch = new StepBatch(model, greedy, 2))
            using (Session a = new Session(model, greedy, seed))
            using (Session b = new Session(model, greedy, seed, batch))
            {
                Session[] both = { a, b };
                var got = new[] { new System.Collections.Generic.List<FollowerFrame>(), new System.Collections.Generic.List<FollowerFrame>() };
                a.SetMusicTrack(track);
                b.SetMusicTrack(track);
                FollowerFrame f = new FollowerFrame();
                int failed;
                for (int i = 0; i < frames; i++)
                {
                    LeaderFrame[] two = { FixtureFrame(leader, i, false), FixtureFrame(leader, i, true) };
                    if (i == 3)
                    {
                        LeaderFrame[] bad = { two[0], two[1] };
                        bad[1].Set(2, float.NaN, 0, 0);
                        Check(batch.PushLeader(both, bad, out failed) == DuoResult.NonFiniteInput && failed == 1, "a NaN frame names session 1");
                        try { batch.PushLeader(new[] { a, a }, two, out failed); Check(false, "a session given twice throws"); }
                        catch (DuolandoException e) { Check(e.Result == DuoResult.InvalidArgument, "twice: " + e.Message); }
                    }
                    DuoResult r = batch.PushLeader(both, two, out failed);
                    if (r == DuoResult.Backlog) break;
                    Check(r == DuoResult.Ok && failed == -1, "batched push " + i + ": " + r);
                    for (int k = 0; k < 2; k++)
                        while (both[k].TryPull(ref f)) got[k].Add(f);
                }
                for (int k = 0; k < 2; k++)
                    Check(SameFrames(got[k].ToArray(), alone[k]), "batched session " + k + " equals the session alone (" + got[k].Count + " frames)");
                Check(!SameFrames(alone[0], alone[1]), "the two leaders give two dances");
            }
        }
        TestSolo(root);
        TestTransflower(root);
        TestTransflowerBatch(root);
        TestPositionsOfAFollower(root, leader, track, frames);
        Check(pulled > frames / 2, "frames pulled: " + pulled);
        Check(rejected > 0, "NaN frames rejected");
        Console.WriteLine("test_unity: " + pulled + " follower frames, " + rejected + " NaN frames rejected, " + failures + " failures");
        return failures == 0 ? 0 : 1;
    }

    static void Throws(Action a, DuoResult want, string contains, string what)
    {
        try { a(); Check(false, what + " throws"); }
        catch (DuolandoException e) { Check(e.Result == want && e.Message.Contains(contains), what + ": " + e.Message); }
    }

    static void ThrowsArgument(Action a, string what)
    {
        try { a(); Check(false, what + " throws"); }
        catch (ArgumentException) { }
    }

    // Pulls every ready frame into all[got * Joints * 3 ...]; returns the new count.
    static int PullAll(SessionBase s, float[] all, int got)
    {
        int n = s.Joints * 3;
        float[] one = new float[n];
        ulong index;
        while (s.TryPullPositions(one, out index))
        {
            Check(index == (ulong)got, "solo frame index " + index + " == " + got);
            if ((got + 1) * n <= all.Length) Array.Copy(one, 0, all, got * n, n);
            got++;
        }
        return got;
    }

    static float MaxAbsDiff(float[] a, float[] b)
    {
        float worst = 0;
        for (int i = 0; i < a.Length && i < b.Length; i++)
        {
            float d = Math.Abs(a[i] - b[i]);
            if (!(d <= worst)) worst = d;   // NaN counts as worst
        }
        return worst;
    }

    // The Transflower paper fixture through TransflowerSession: the recorded noise replayed
    // gives the authors' frames (output.npy) within the case's 9.7e-6 relative tolerance
    // (docs/TRANSFLOWER.md); a seed repeats its dance after Reset; the wrong family throws.
    static void TestTransflower(string root)
    {
        string dir = Path.Combine(root, "tests/fixtures/transflower_paper");
        float[] motion = ReadNpyF32(Path.Combine(dir, "in_expmap_scaled_20.npy"));
        float[] audio = ReadNpyF32(Path.Combine(dir, "in_audio_feats_scaled_20.npy"));
        float[] noise = ReadNpyF32(Path.Combine(dir, "noise.npy"));
        float[] want = ReadNpyF32(Path.Combine(dir, "output.npy"));
        Check(Marshal.SizeOf(typeof(TransflowerInfo)) == 48 && Marshal.SizeOf(typeof(TransflowerConfig)) == 32, "Transflower struct sizes");
        using (Model duet = Model.OpenFile(Path.Combine(root, "tests/fixtures/tiny/model.duo")))
            ThrowsArgument(() => new TransflowerSession(duet, new TransflowerConfig(), motion, null), "TransflowerSession on a Duolando model");
        using (Model model = Model.OpenFile(Path.Combine(dir, "model.duo")))
        {
            Check(model.Family == ModelFamily.Transflower, "family Transflower");
            Throws(() => TransflowerSession.Preset(model, "interactive"), DuoResult.InvalidArgument, "realtime", "an unknown Transflower preset");
            TransflowerConfig exact = TransflowerSession.Preset(model, "exact");
            Check(exact.Refresh == 1, "exact: refresh 1");
            using (TransflowerSession s = new TransflowerSession(model, exact, Slice(motion, 0, 12 * 11), null))
            {
                int c = (int)s.Info.Channels, d = (int)s.Info.AudioFeatures, nz = (int)s.Info.NoiseFloats;
                float[] frame = new float[c];
                float[] z = new float[nz];
                int got = 0;
                double worst = 0, scale = 1;
                ulong index;
                for (int r = 0; r * d < audio.Length; r++)
                {
                    s.PushAudio(Slice(audio, r * d, d));
                    while ((got + 1) * nz <= noise.Length)
                    {
                        Array.Copy(noise, got * nz, z, 0, nz);
                        if (!s.TryPullFrame(frame, out index, z)) break;
                        Check(index == (ulong)got, "frame index");
                        for (int j = 0; j < c; j++)
                        {
                            worst = Math.Max(worst, Math.Abs(frame[j] - want[got * c + j]));
                            scale = Math.Max(scale, Math.Abs(want[got * c + j]));
                        }
                        got++;
                    }
                }
                Check(got * c == want.Length, "every frame of the golden");
                Check(worst / scale <= 9.7e-6, "Transflower frames vs the authors': rel " + (worst / scale));
                float[] first = null;
                for (int k = 0; k < 2; k++)
                {
                    s.Reset(3);
                    Check(!s.TryPullFrame(frame, out index), "no audio: not ready");
                    s.PushAudio(Slice(audio, 0, (int)s.Info.AudioWindow * d));
                    Check(s.TryPullFrame(frame, out index) && index == 0, "a seeded frame");
                    if (first == null) first = (float[])frame.Clone();
                }
                Check(first != null && System.Linq.Enumerable.SequenceEqual(first, frame), "the same seed, the same frame");
            }
        }
    }

    // `rows` rows of the fixture's audio (d floats each), cycled.
    static float[] Cycled(float[] audio, int d, int rows)
    {
        float[] r = new float[rows * d];
        for (int i = 0; i < rows; i++) Array.Copy(audio, (i % (audio.Length / d)) * d, r, i * d, d);
        return r;
    }

    static unsafe bool SameBits(float[] a, float[] b)
    {
        if (a.Length != b.Length) return false;
        fixed (float* pa = a, pb = b)
            for (int i = 0; i < a.Length; i++)
                if (((int*)pa)[i] != ((int*)pb)[i]) return false;
        return true;
    }

    // Every ready frame of s appended to `all` (indices checked); returns how many were taken.
    static int PullAllFrames(TransflowerSession s, System.Collections.Generic.List<float> all)
    {
        int c = (int)s.Info.Channels, n = 0;
        float[] frame = new float[c];
        ulong index;
        while (s.TryPullFrame(frame, out index))
        {
            Check(index == (ulong)(all.Count / c), "frame index " + index);
            all.AddRange(frame);
            n++;
        }
        return n;
    }

    // Three Batched sessions (seeds 21, 22, 23) through one TransflowerStepBatch (in its own
    // unmanaged memory) give each session's frames alone, bit for bit; a batched session's pull
    // does not step; the refusals (another family's model, a session twice, another model's
    // session, a null, more than MaxSessions, a backlogged session by index, a disposed batch).
    static void TestTransflowerBatch(string root)
    {
        string dir = Path.Combine(root, "tests/fixtures/transflower_paper");
        float[] motion = Slice(ReadNpyF32(Path.Combine(dir, "in_expmap_scaled_20.npy")), 0, 12 * 11);
        float[] fixture = ReadNpyF32(Path.Combine(dir, "in_audio_feats_scaled_20.npy"));
        using (Model duet = Model.OpenFile(Path.Combine(root, "tests/fixtures/tiny/model.duo")))
            Throws(() => new TransflowerStepBatch(duet), DuoResult.InvalidArgument, "needs a Transflower model", "a step batch of a Duolando model");
        using (Model model = Model.OpenFile(Path.Combine(dir, "model.duo")))
        using (Model other = Model.OpenFile(Path.Combine(dir, "model.duo")))
        {
            TransflowerConfig c = TransflowerSession.Preset(model, "exact");
            c.PendingFrames = 2;
            TransflowerInfo info;
            using (TransflowerSession probe = new TransflowerSession(model, c, motion, null)) info = probe.Info;
            int d = (int)info.AudioFeatures, w = (int)info.AudioWindow, rows = 30;
            float[] audio = Cycled(fixture, d, rows);
            var alone = new System.Collections.Generic.List<float>[3];
            for (int k = 0; k < 3; k++)
            {
                c.RngSeed = (ulong)(21 + k);
                alone[k] = new System.Collections.Generic.List<float>();
                using (TransflowerSession s = new TransflowerSession(model, c, motion, null))
                    for (int r = 0; r < rows; r++)
                    {
                        s.PushAudio(Slice(audio, r * d, d));
                        PullAllFrames(s, alone[k]);
                    }
                Check(alone[k].Count == (rows - w + 1) * (int)info.Channels, "frames alone: " + alone[k].Count);
            }
            Check(!SameBits(alone[0].ToArray(), alone[1].ToArray()), "two seeds, two dances");
            Check(TransflowerStepBatch.Bytes(model) > 0, "batch bytes");
            c.Batched = 1;
            var ss = new TransflowerSession[3];
            for (int k = 0; k < 3; k++)
            {
                c.RngSeed = (ulong)(21 + k);
                ss[k] = new TransflowerSession(model, c, motion, null);
            }
            TransflowerSession stranger = new TransflowerSession(other, c, motion, null);
            var got = new System.Collections.Generic.List<float>[3];
            for (int k = 0; k < 3; k++) got[k] = new System.Collections.Generic.List<float>();
            using (TransflowerStepBatch batch = new TransflowerStepBatch(model, true))
            {
                int stepped, failed;
                Throws(() => batch.Step(new[] { ss[0], ss[1], ss[0] }, out stepped, out failed), DuoResult.InvalidArgument, "sessions[2] is sessions[0] again", "a session given twice");
                Throws(() => batch.Step(new[] { ss[0], stranger }, out stepped, out failed), DuoResult.InvalidArgument, "sessions[1] is a session of another model", "a session of another model");
                ThrowsArgument(() => batch.Step(new[] { ss[0], null }, out stepped, out failed), "a null session");
                var many = new TransflowerSession[TransflowerStepBatch.MaxSessions + 1];
                for (int i = 0; i < many.Length; i++) many[i] = ss[0];
                ThrowsArgument(() => batch.Step(many, out stepped, out failed), "more than MaxSessions");
                Check(batch.Step(ss, out stepped, out failed) == DuoResult.Ok && stepped == 0 && failed == -1, "no audio: none stepped");
                for (int k = 0; k < 3; k++) ss[k].PushAudio(Slice(audio, 0, w * d));
                float[] frame = new float[info.Channels];
                ulong index;
                Check(!ss[0].TryPullFrame(frame, out index), "a batched session's pull does not step");
                // Backlog: session 2's two pending frames made and not pulled.
                ss[2].PushAudio(Slice(audio, w * d, d));
                for (int k = 0; k < 2; k++)
                    Check(batch.Step(new[] { ss[2] }, out stepped, out failed) == DuoResult.Ok && stepped == 1, "session 2 stepped");
                Check(batch.Step(ss, out stepped, out failed) == DuoResult.Backlog && failed == 2 && stepped == 0, "backlog names session 2: " + failed);
                for (int r = w; r <= rows; r++)
                {
                    if (r < rows)
                        for (int k = 0; k < 3; k++)
                            if (k < 2 || r > w) ss[k].PushAudio(Slice(audio, r * d, d));
                    do
                    {
                        for (int k = 0; k < 3; k++) PullAllFrames(ss[k], got[k]);
                        Check(batch.Step(ss, out stepped, out failed) == DuoResult.Ok && failed == -1, "a batch step");
                    } while (stepped > 0);
                }
                for (int k = 0; k < 3; k++) PullAllFrames(ss[k], got[k]);
                for (int k = 0; k < 3; k++)
                    Check(SameBits(got[k].ToArray(), alone[k].ToArray()), "batched session " + k + " equals the session alone, bit for bit (" + got[k].Count + " floats)");
                batch.Dispose();
                try { batch.Step(ss, out stepped, out failed); Check(false, "a disposed batch throws"); }
                catch (ObjectDisposedException) { }
            }
            using (TransflowerStepBatch own = new TransflowerStepBatch(model))
            {
                int stepped, failed;
                Check(own.Step(ss, out stepped, out failed) == DuoResult.Ok && stepped == 0, "a library-allocated batch: nothing left to step");
            }
            for (int k = 0; k < 3; k++) ss[k].Dispose();
            stranger.Dispose();
            Console.WriteLine("test_unity: 3 batched Transflower sessions through a TransflowerStepBatch, " + got[0].Count / (int)info.Channels + " frames each, as alone bit for bit");
        }
    }

    static float[] Slice(float[] a, int from, int n)
    {
        float[] r = new float[n];
        Array.Copy(a, from, r, 0, n);
        return r;
    }

    // The Bailando fixture through SoloSession: the authors' positions within 1e-5 m.
    static void TestSolo(string root)
    {
        string dir = Path.Combine(root, "tests/fixtures/bailando_rollout_btiny_demo_odd");
        float[] rows = ReadNpyF32(Path.Combine(dir, "music.npy"));      // 21 x 438
        float[] want = ReadNpyF32(Path.Combine(dir, "pos3d.npy"));      // 192 x 72
        uint[] seed = { 15, 14 };                                        // meta.json seed_tokens
        Check(rows.Length == 21 * 438 && want.Length == 192 * 72, "solo fixture shapes");
        using (Model duet = Model.OpenFile(Path.Combine(root, "tests/fixtures/tiny/model.duo")))
        {
            Check(duet.Family == ModelFamily.Duolando && !duet.IsSolo && duet.SeedTokenCount == 5, "the tiny model is a Duolando model");
            ThrowsArgument(() => new SoloSession(duet, duet.MinimumConfig(), new uint[] { 1, 2 }), "SoloSession on a Duolando model");
            Check(duet.Preset("live-music").MusicLookahead == 0, "Duolando preset live-music");
        }
        using (Model model = Model.OpenFile(Path.Combine(root, "tests/fixtures/bailando_btiny/model.duo")))
        {
            ModelInfo info = model.Info;
            Check(info.Family == ModelFamily.Bailando && model.IsSolo && model.Family == ModelFamily.Bailando, "family Bailando");
            Check(info.Joints == 24 && info.MusicFeatures == 438 && info.Fps == 60 && info.FramesPerToken == 8, "solo info: " + info.Joints + " joints, " + info.MusicFeatures + " features, " + info.Fps + " fps");
            Check(model.SeedTokenCount == 2, "2 seed tokens");
            SessionConfig exact = model.Preset("exact");
            Check(exact.Lookahead == 0 && exact.EncFuture == 0 && exact.MusicLookahead == 0 && exact.LatPast == 0 && exact.Staggered == 0, "solo preset: Duolando-only fields 0");
            Throws(() => model.Preset("live-music"), DuoResult.InvalidArgument, "exact", "a Duolando-only preset on a solo model");
            Throws(() => model.SeedTokens(new float[8 * 165], new float[8 * 165]), DuoResult.InvalidArgument, "Bailando", "SeedTokens on a solo model");
            SessionConfig bad = exact;
            bad.Lookahead = 1;
            Throws(() => new SoloSession(model, bad, seed), DuoResult.InvalidArgument, "lookahead", "a solo config with lookahead");
            ThrowsArgument(() => new SoloSession(model, exact, new uint[] { 1, 2, 3, 4, 5 }), "5 seed tokens for a solo model");

            float[] got = new float[want.Length];
            float[] again = new float[want.Length];
            int n = 0, backlogs = 0;
            using (SoloSession s = new SoloSession(model, exact, seed))
            {
                Check(s.Joints == SoloSession.SoloJoints && s.MusicFeatures == 438 && s.Fps == 60, "solo session sizes");
                Check(s.LatencyFrames % 8 == 0, "solo latency " + s.LatencyFrames + " frames (whole tokens)");
                float[] one = new float[72];
                ulong index;
                Check(!s.TryPullPositions(one, out index), "nothing before music");
                Throws(() => s.Finish(), DuoResult.InvalidArgument, "music", "Finish before any music row");
                ThrowsArgument(() => s.TryPullPositions(new float[71], out index), "a 71-float positions buffer");
                Throws(() => s.PushMusic(new float[437]), DuoResult.InvalidArgument, "", "a 437-float music row");
                for (int r = 0; r < 21; r++)
                {
                    if (r == 5)
                    {
                        float[] nan = new float[438];
                        Array.Copy(rows, r * 438, nan, 0, 438);
                        nan[100] = float.NaN;
                        Check(s.PushMusic(nan) == DuoResult.NonFiniteInput, "a NaN row is refused");
                    }
                    DuoResult res = s.PushMusic(rows, r * 438, 438);
                    if (res == DuoResult.Backlog) { backlogs++; n = PullAll(s, got, n); res = s.PushMusic(rows, r * 438, 438); }
                    Check(res == DuoResult.Ok, "push row " + r + ": " + res);
                    n = PullAll(s, got, n);
                }
                s.Finish();
                s.Finish();   // again: nothing
                n = PullAll(s, got, n);
                Check(n == 192, "192 solo frames (got " + n + ")");
                float err = MaxAbsDiff(got, want);
                Console.WriteLine("test_unity: solo " + n + " frames pushed row by row, max abs err " + err.ToString("E2") + " m, latency " + s.LatencyFrames + " frames");
                Check(err <= 1e-5f, "solo positions == golden within 1e-5 (max " + err + ")");
                Check(!s.TryPullPositions(one, out index), "nothing after the end");

                // Again from frame 0, the rows given as one track.
                s.Reset(seed);
                ThrowsArgument(() => s.Reset(new uint[] { 15 }), "a 1-token reset");
                s.SetMusicTrack(rows);
                s.Finish();
                int m = PullAll(s, again, 0);
                Check(m == 192 && MaxAbsDiff(again, got) == 0, "after Reset, the track gives the same dance (" + m + " frames)");

                // Unity and Unreal axes.
                float[] u = (float[])got.Clone(), e = (float[])got.Clone();
                Positions.Convert(u, 72 * 10, 24, Coords.Unity);
                Positions.Convert(e, 72 * 10, 24, Coords.Unreal);
                bool axes = true;
                for (int j = 0; j < 24; j++)
                {
                    Vec3 p = Positions.Get(got, 72 * 10, j), pu = Positions.Get(u, 72 * 10, j), pe = Positions.Get(e, 72 * 10, j);
                    axes &= pu.X == -p.X && pu.Y == p.Y && pu.Z == p.Z;
                    axes &= Math.Abs(pe.X - 100 * p.Z) < 1e-4 && Math.Abs(pe.Y + 100 * p.X) < 1e-4 && Math.Abs(pe.Z - 100 * p.Y) < 1e-4;
                }
                Check(axes && u[0] == got[0] && u[72 * 11] == got[72 * 11], "Positions.Convert: Unity (-x, y, z), Unreal 100 (z, -x, y), only the frame asked");
            }
            // A Session (the follower class) on the solo model: the Duolando-only calls throw
            // the library's message; the solo calls work.
            using (Session s = new Session(model, exact, seed))
            {
                LeaderFrame lf = new LeaderFrame();
                FollowerFrame ff = new FollowerFrame();
                Throws(() => s.PushLeader(ref lf), DuoResult.InvalidArgument, "Bailando", "PushLeader on a solo model");
                Throws(() => s.TryPull(ref ff), DuoResult.InvalidArgument, "Bailando", "TryPull on a solo model");
                Throws(() => new StepBatch(model, exact, 1), DuoResult.InvalidArgument, "Bailando", "a StepBatch of a solo model");
                s.SetMusicTrack(rows);
                s.Finish();
                float[] third = new float[want.Length];
                int k = PullAll(s, third, 0);
                Check(k == 192 && MaxAbsDiff(third, got) == 0, "the solo calls of a Session on a solo model");
            }
            Console.WriteLine("test_unity: solo: " + backlogs + " music backlog(s)");
        }
    }

    // TryPullPositions on a Duolando session gives its follower frames' positions.
    static void TestPositionsOfAFollower(string root, float[] leader, float[] track, int frames)
    {
        using (Model model = Model.OpenFile(Path.Combine(root, "tests/fixtures/tiny/model.duo")))
        using (Session a = new Session(model, model.MinimumConfig(), new uint[] { 1, 2, 3, 4, 5 }))
        using (Session b = new Session(model, model.MinimumConfig(), new uint[] { 1, 2, 3, 4, 5 }))
        {
            ThrowsArgument(() => a.Reset(new uint[] { 1, 2 }), "a 2-token reset of a Duolando session");
            a.SetMusicTrack(track);
            b.SetMusicTrack(track);
            FollowerFrame f = new FollowerFrame();
            float[] p = new float[165];
            ulong index;
            int same = 0, total = 0;
            for (int i = 0; i < frames && i < 40; i++)
            {
                LeaderFrame fr = FixtureFrame(leader, i, false);
                if (a.PushLeader(ref fr) != DuoResult.Ok || b.PushLeader(ref fr) != DuoResult.Ok) break;
                while (a.TryPull(ref f))
                {
                    Check(b.TryPullPositions(p, out index) && index == f.Index, "positions of follower frame " + f.Index);
                    bool eq = true;
                    for (int j = 0; j < 55; j++)
                    {
                        Vec3 v = f.Position(j);
                        eq &= v.X == p[3 * j] && v.Y == p[3 * j + 1] && v.Z == p[3 * j + 2];
                    }
                    if (eq) same++;
                    total++;
                }
            }
            Check(total > 0 && same == total, "Duolando TryPullPositions == FollowerFrame positions (" + same + "/" + total + ")");
        }
    }

    static LeaderFrame FixtureFrame(float[] leader, int i, bool mirrored)
    {
        LeaderFrame fr = new LeaderFrame();
        for (int j = 0; j < 55; j++)
            fr.Set(j, mirrored ? -leader[i * 165 + 3 * j] : leader[i * 165 + 3 * j], leader[i * 165 + 3 * j + 1], leader[i * 165 + 3 * j + 2]);
        return fr;
    }

    static unsafe bool SameFrames(FollowerFrame[] x, FollowerFrame[] y)
    {
        if (x.Length != y.Length || x.Length == 0) return false;
        int size = Marshal.SizeOf(typeof(FollowerFrame));
        for (int i = 0; i < x.Length; i++)
        {
            FollowerFrame p = x[i], q = y[i];
            byte* a = (byte*)&p;
            byte* b = (byte*)&q;
            for (int k = 0; k < size; k++)
                if (a[k] != b[k]) return false;
        }
        return true;
    }

    static float[] SubArray(float[] a, int start, int n)
    {
        float[] r = new float[n];
        Array.Copy(a, start, r, 0, n);
        return r;
    }
}

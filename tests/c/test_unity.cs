// Smoke test of the Unity wrapper (integrations/unity/Runtime/Duolando.cs) under
// Mono against libduolando.so: struct layouts, errors as exceptions, a
// session fed the fixture leader (with NaN glitches replaced by the last
// good frame) producing finite frames, converted to Unity coordinates; two
// sessions stepped through a StepBatch equal to each stepped alone.
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
        Check(Marshal.SizeOf(typeof(SessionConfig)) == 56, "SessionConfig is 56 bytes");
        Check(Marshal.SizeOf(typeof(ModelInfo)) == 32, "ModelInfo is 32 bytes");
        Check(Model.Version == "0.1.0", "version");
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
            config.Sampling = SamplingMode.TopK;
            config.TopK = 2;
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
            using (StepBatch batch = new StepBatch(model, greedy, 2))
            using (Session a = new Session(model, greedy, seed))
            using (Session b = new Session(model, greedy, seed))
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
        Check(pulled > frames / 2, "frames pulled: " + pulled);
        Check(rejected > 0, "NaN frames rejected");
        Console.WriteLine("test_unity: " + pulled + " follower frames, " + rejected + " NaN frames rejected, " + failures + " failures");
        return failures == 0 ? 0 : 1;
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

// Runs the Unity package's sample (integrations/unity/Samples~/HumanoidFollower)
// under Mono against the real libduolando and the TEST STUB UnityEngine
// (tests/unity/UnityEngineStub.cs): Start loads the demo model and data from
// assets/ (as StreamingAssets), Update is called as a player loop would at
// 30 fps for more than the whole demo clip (so the sample loops once), and
// the stub humanoid's bones must be driven with finite unit rotations and a
// moving hips position. The sample's world-rotation composition is checked
// against an independent computation in double-precision 3x3 matrices
// (FK in SMPL-X, then the change of basis P G P^T to Unity axes).
// Usage: mono test_sample.exe <repo root>   (.ci/ffi.sh)
using System;
using System.IO;
using System.Reflection;
using System.Threading;
using Duolando;
using Duolando.Samples;
using UnityEngine;

static class TestSample
{
    static int failures;

    static void Check(bool ok, string what)
    {
        if (!ok) { failures++; Console.Error.WriteLine("FAIL: " + what); }
    }

    static void Call(object o, string method)
    {
        MethodInfo m = o.GetType().GetMethod(method, BindingFlags.Instance | BindingFlags.NonPublic | BindingFlags.Public);
        object r = m.Invoke(o, null);
        var e = r as System.Collections.IEnumerator;
        if (e != null) ((MonoBehaviour)o).StartCoroutine(e);
    }

    static bool Finite(float v) { return !float.IsNaN(v) && !float.IsInfinity(v); }

    static double[,] Mat(double x, double y, double z, double w)
    {
        return new double[,] {
            { 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w) },
            { 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w) },
            { 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y) } };
    }

    static double[,] Mul(double[,] a, double[,] b)
    {
        var c = new double[3, 3];
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++)
                for (int k = 0; k < 3; k++) c[i, j] += a[i, k] * b[k, j];
        return c;
    }

    // Independent check of DuolandoHumanoidFollower.WorldRotations on real frames.
    static void CheckWorldRotations(string root)
    {
        using (Model model = Model.OpenFile(Path.Combine(root, "assets", "demo.duo")))
        using (Session s = new Session(model, model.MinimumConfig(), new uint[] { 0, 0, 0, 0, 0 }))
        {
            int rows, cols;
            float[] leader = Npy.ReadFloat32(File.ReadAllBytes(Path.Combine(root, "assets", "demo_leader_pos3d.npy")), out rows, out cols);
            float[] music = Npy.ReadFloat32(File.ReadAllBytes(Path.Combine(root, "assets", "demo_music.npy")), out rows, out cols);
            s.SetMusicTrack(music);
            LeaderFrame lf = default(LeaderFrame);
            FollowerFrame f = default(FollowerFrame);
            var g = new Quaternion[FollowerFrame.Joints];
            int checkedFrames = 0;
            double worst = 0;
            for (int t = 0; t < 40; t++)
            {
                for (int j = 0; j < 55; j++) lf.Set(j, leader[t * 165 + 3 * j], leader[t * 165 + 3 * j + 1], leader[t * 165 + 3 * j + 2]);
                Check(s.PushLeader(ref lf) == DuoResult.Ok, "push");
                while (s.TryPull(ref f))
                {
                    // Reference: FK of the SMPL-X local rotations in double precision.
                    var G = new double[55][,];
                    for (int j = 0; j < 55; j++)
                    {
                        Quat q = f.LocalRotation(j);
                        double[,] L = Mat(q.X, q.Y, q.Z, q.W);
                        int p = DuolandoHumanoidFollower.Parent[j];
                        G[j] = p < 0 ? L : Mul(G[p], L);
                    }
                    FollowerFrame u = f;
                    u.ConvertFromSmplX(Coords.Unity);
                    DuolandoHumanoidFollower.WorldRotations(ref u, g);
                    double[] P = { -1, 1, 1 };   // Unity: x mirrored
                    for (int j = 0; j < 55; j++)
                    {
                        double[,] M = Mat(g[j].x, g[j].y, g[j].z, g[j].w);
                        for (int a = 0; a < 3; a++)
                            for (int b = 0; b < 3; b++)
                                worst = Math.Max(worst, Math.Abs(M[a, b] - P[a] * G[j][a, b] * P[b]));
                    }
                    checkedFrames++;
                }
            }
            Console.WriteLine("world rotations: " + checkedFrames + " frames x 55 joints, worst matrix entry difference " + worst.ToString("E2"));
            Check(checkedFrames >= 30, "frames pulled for the rotation check");
            Check(worst < 1e-4, "sample world rotations == P (FK of local rotations) P^T");
        }
    }

    static int Main(string[] args)
    {
        string root = args[0];
        CheckWorldRotations(root);

        Application.streamingAssetsPath = Path.Combine(root, "assets");
        // A stub humanoid: character turned 90 degrees about y, every bone with a
        // non-identity rest rotation, no UpperChest (optional in Unity avatars).
        var character = new Animator();
        character.transform.position = new Vector3(1, 0, 2);
        character.transform.rotation = Quaternion.AngleAxis(90, new Vector3(0, 1, 0));
        foreach (HumanBodyBones b in Enum.GetValues(typeof(HumanBodyBones)))
        {
            if (b == HumanBodyBones.UpperChest || b == HumanBodyBones.LastBone) continue;
            var t = new Transform();
            t.rotation = character.transform.rotation * Quaternion.AngleAxis(10 + (int)b, new Vector3(1, 0, 0));
            t.position = character.transform.TransformPoint(new Vector3(0, b == HumanBodyBones.Hips ? 0.9f : 1.2f, 0));
            character.StubBones[b] = t;
        }
        Vector3 hips0 = character.StubBones[HumanBodyBones.Hips].position;

        var sample = new DuolandoHumanoidFollower();
        sample.follower = character;
        Call(sample, "Start");
        Check(sample.Error == null, "Start: " + sample.Error);

        // 900 updates at 30 fps: more than the 748-frame clip, so the sample loops.
        Time.deltaTime = 1f / 30f;
        for (int i = 0; i < 900 && sample.Error == null; i++)
        {
            Call(sample, "Update");
            Thread.Sleep(2);
        }
        for (int i = 0; i < 200; i++) { Thread.Sleep(5); Call(sample, "Update"); }
        Check(sample.Error == null, "worker: " + sample.Error);
        Console.WriteLine("sample: " + sample.FramesApplied + " follower frames applied to the stub humanoid");
        Check(sample.FramesApplied >= 50, "follower frames applied (>= 50; the main thread applies only the newest)");
        Console.WriteLine("sample: restarted " + sample.Restarts + " time(s) at the end of the 748-frame clip");
        Check(sample.Restarts >= 1, "the sample looped (reset + music track again)");

        int driven = 0, moved = 0;
        foreach (var kv in character.StubBones)
        {
            Quaternion q = kv.Value.rotation;
            double n = Math.Sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w);
            Check(Finite(q.x) && Finite(q.y) && Finite(q.z) && Finite(q.w) && Math.Abs(n - 1) < 1e-3, kv.Key + " rotation is a finite unit quaternion");
            driven++;
            Quaternion rest = character.transform.rotation * Quaternion.AngleAxis(10 + (int)kv.Key, new Vector3(1, 0, 0));
            if (Math.Abs(q.x - rest.x) + Math.Abs(q.y - rest.y) + Math.Abs(q.z - rest.z) + Math.Abs(q.w - rest.w) > 1e-3) moved++;
        }
        Vector3 hips = character.StubBones[HumanBodyBones.Hips].position;
        Check(Finite(hips.x) && Finite(hips.y) && Finite(hips.z), "hips position finite");
        Vector3 d = hips - hips0;
        Check(Math.Abs(d.x) + Math.Abs(d.y) + Math.Abs(d.z) > 1e-4, "hips moved");
        Check(hips.y > 0.3f && hips.y < 1.5f, "hips height plausible: " + hips);
        Console.WriteLine("bones: " + driven + " driven, " + moved + " away from rest; hips " + hips);
        Check(moved >= 20, "at least 20 bones posed away from their rest rotation");

        Call(sample, "OnDestroy");
        if (failures == 0) Console.WriteLine("test_sample: all checks passed");
        return failures == 0 ? 0 : 1;
    }
}

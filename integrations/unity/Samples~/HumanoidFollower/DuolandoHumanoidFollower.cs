// DuolandoHumanoidFollower — sample: the demo model dances as the follower
// of the recorded demo leader, driving a Humanoid character.
//
// Scene setup (no .unity scene file is shipped):
//   1. Copy assets/demo.duo, demo_leader_pos3d.npy, demo_music.npy and
//      demo_follower_start.npy of the duolando repository to
//      Assets/StreamingAssets/.
//   2. Add a character whose Animator has a Humanoid avatar, standing in
//      T-pose at Start (no Animator Controller, or one that is disabled):
//      its rest rotations are read then.
//   3. Add this component to any GameObject and drag the character's
//      Animator into "Follower".
//
// How the bones are driven: the library gives each joint's LOCAL rotation
// (relative to its SMPL-X parent, in SMPL-X rest axes: T-pose, facing +z).
// After converting the frame to Unity coordinates the sample composes
// them down the SMPL-X tree into world rotations G[j] and sets
//   bone.rotation = character.rotation * G[j] * rest[bone]
// where rest[bone] is the bone's rotation relative to the character at
// Start. So a character whose T-pose matches the SMPL-X rest pose (arms
// horizontal, palms down) follows the joints; bones Unity lacks (an
// unmapped UpperChest, toes, jaw, eyes, fingers) are skipped and their
// children still get their own world rotations. The hips follow the
// follower's root (pelvis) position, scaled by the character's hip height.
//
// Threads: PushLeader runs the model, so it runs on a worker thread; the
// main thread only counts due frames (30 fps) and applies the newest
// follower frame.
using System;
using System.Collections;
using System.IO;
using System.Threading;
using Duolando;
using UnityEngine;
#if UNITY_ANDROID && !UNITY_EDITOR
using UnityEngine.Networking;
#endif

namespace Duolando.Samples
{
    public sealed class DuolandoHumanoidFollower : MonoBehaviour
    {
        [Tooltip("The follower character: an Animator with a Humanoid avatar, in T-pose at Start.")]
        public Animator follower;
        [Tooltip("Files in StreamingAssets.")]
        public string modelFile = "demo.duo";
        public string leaderFile = "demo_leader_pos3d.npy";
        public string musicFile = "demo_music.npy";
        public string followerStartFile = "demo_follower_start.npy";
        [Tooltip("Latency 0 frames (on) or the reference budget (off: several seconds of delay).")]
        public bool lowLatency = true;
        [Tooltip("Start again from frame 0 at the end of the recorded leader.")]
        public bool loop = true;
        [Tooltip("Pelvis height of the SMPL-X rest rig the model was trained on (metres).")]
        public float modelHipHeight = 0.935f;

        /// <summary>Follower frames applied to the character so far.</summary>
        public long FramesApplied { get; private set; }
        /// <summary>Times the recorded leader ran out and the session started over.</summary>
        public int Restarts { get { return restarts; } }
        /// <summary>Set when loading or the worker failed (also logged).</summary>
        public string Error { get; private set; }

        /// <summary>SMPL-X joint j -> the Humanoid bone it drives (LastBone: none).</summary>
        public static readonly HumanBodyBones[] BoneOfJoint =
        {
            HumanBodyBones.Hips, HumanBodyBones.LeftUpperLeg, HumanBodyBones.RightUpperLeg, HumanBodyBones.Spine,   // 0-3 pelvis, hips, spine1
            HumanBodyBones.LeftLowerLeg, HumanBodyBones.RightLowerLeg, HumanBodyBones.Chest,                         // 4-6 knees, spine2
            HumanBodyBones.LeftFoot, HumanBodyBones.RightFoot, HumanBodyBones.UpperChest,                            // 7-9 ankles, spine3
            HumanBodyBones.LeftToes, HumanBodyBones.RightToes, HumanBodyBones.Neck,                                  // 10-12 feet, neck
            HumanBodyBones.LeftShoulder, HumanBodyBones.RightShoulder, HumanBodyBones.Head,                          // 13-15 collars, head
            HumanBodyBones.LeftUpperArm, HumanBodyBones.RightUpperArm, HumanBodyBones.LeftLowerArm,                  // 16-18 shoulders, l elbow
            HumanBodyBones.RightLowerArm, HumanBodyBones.LeftHand, HumanBodyBones.RightHand,                         // 19-21 r elbow, wrists
            HumanBodyBones.Jaw, HumanBodyBones.LeftEye, HumanBodyBones.RightEye,                                     // 22-24
            HumanBodyBones.LeftIndexProximal, HumanBodyBones.LeftIndexIntermediate, HumanBodyBones.LeftIndexDistal,  // 25-27
            HumanBodyBones.LeftMiddleProximal, HumanBodyBones.LeftMiddleIntermediate, HumanBodyBones.LeftMiddleDistal,
            HumanBodyBones.LeftLittleProximal, HumanBodyBones.LeftLittleIntermediate, HumanBodyBones.LeftLittleDistal,
            HumanBodyBones.LeftRingProximal, HumanBodyBones.LeftRingIntermediate, HumanBodyBones.LeftRingDistal,
            HumanBodyBones.LeftThumbProximal, HumanBodyBones.LeftThumbIntermediate, HumanBodyBones.LeftThumbDistal,  // 37-39
            HumanBodyBones.RightIndexProximal, HumanBodyBones.RightIndexIntermediate, HumanBodyBones.RightIndexDistal,
            HumanBodyBones.RightMiddleProximal, HumanBodyBones.RightMiddleIntermediate, HumanBodyBones.RightMiddleDistal,
            HumanBodyBones.RightLittleProximal, HumanBodyBones.RightLittleIntermediate, HumanBodyBones.RightLittleDistal,
            HumanBodyBones.RightRingProximal, HumanBodyBones.RightRingIntermediate, HumanBodyBones.RightRingDistal,
            HumanBodyBones.RightThumbProximal, HumanBodyBones.RightThumbIntermediate, HumanBodyBones.RightThumbDistal, // 52-54
        };

        /// <summary>SMPL-X parent of each joint (-1: the pelvis). Parents precede children.</summary>
        public static readonly int[] Parent =
        {
            -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15, 20,
            25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46,
            47, 21, 49, 50, 21, 52, 53,
        };

        const int J = FollowerFrame.Joints;
        Model model;
        Session session;
        uint[] seed;
        float[] music;
        float[] leader;          // frames x 165, SMPL-X metres
        int leaderFrames;
        Thread worker;
        volatile bool running;
        volatile bool workerFailed;
        int due;                 // leader frames the worker owes (Interlocked)
        int restarts;            // Interlocked
        readonly AutoResetEvent wake = new AutoResetEvent(false);
        readonly object gate = new object();
        FollowerFrame newest;    // guarded by gate
        bool fresh;              // guarded by gate
        FollowerFrame applying;
        double clock;
        readonly Transform[] bones = new Transform[J];
        readonly Quaternion[] rest = new Quaternion[J];
        readonly Quaternion[] world = new Quaternion[J];
        float positionScale = 1f;

        IEnumerator Start()
        {
            byte[] modelBytes = null, leaderBytes = null, musicBytes = null, startBytes = null;
            yield return StartCoroutine(Load(modelFile, b => modelBytes = b));
            yield return StartCoroutine(Load(leaderFile, b => leaderBytes = b));
            yield return StartCoroutine(Load(musicFile, b => musicBytes = b));
            yield return StartCoroutine(Load(followerStartFile, b => startBytes = b));
            if (Error != null) yield break;
            try
            {
                Begin(modelBytes, leaderBytes, musicBytes, startBytes);
            }
            catch (Exception e)
            {
                Fail(e.Message);
            }
        }

        void Begin(byte[] modelBytes, byte[] leaderBytes, byte[] musicBytes, byte[] startBytes)
        {
            if (follower == null || !follower.isHuman)
                throw new InvalidOperationException("Follower must be an Animator with a Humanoid avatar");
            model = Model.OpenCopy(modelBytes);           // a copy in native memory: works inside an APK too
            ModelInfo info = model.Info;
            int leaderCols, musicCols, startRows, startCols;
            leader = Npy.ReadFloat32(leaderBytes, out leaderFrames, out leaderCols);
            int musicFrames;
            music = Npy.ReadFloat32(musicBytes, out musicFrames, out musicCols);
            float[] start = Npy.ReadFloat32(startBytes, out startRows, out startCols);
            if (leaderCols != J * 3 || startCols != J * 3 || musicCols != (int)info.MusicFeatures)
                throw new InvalidDataException("unexpected .npy shapes");
            int seedFrames = Math.Min(startRows, leaderFrames);
            float[] leaderStart = new float[seedFrames * J * 3];
            Array.Copy(leader, leaderStart, leaderStart.Length);
            float[] followerStart = new float[seedFrames * J * 3];
            Array.Copy(start, followerStart, followerStart.Length);
            seed = model.SeedTokens(followerStart, leaderStart);
            session = new Session(model, lowLatency ? model.MinimumConfig() : model.ReferenceConfig(), seed);
            session.SetMusicTrack(music);
            Debug.Log("Duolando " + Model.Version + ": " + leaderFrames + " leader frames, latency "
                      + session.LatencyFrames + " frames");

            Quaternion characterInverse = Quaternion.Inverse(follower.transform.rotation);
            for (int j = 0; j < J; j++)
            {
                bones[j] = follower.GetBoneTransform(BoneOfJoint[j]);     // null when the avatar lacks it
                if (bones[j] != null) rest[j] = characterInverse * bones[j].rotation;
            }
            if (bones[0] == null) throw new InvalidOperationException("The avatar has no Hips bone");
            float hipHeight = follower.transform.InverseTransformPoint(bones[0].position).y;
            positionScale = hipHeight > 0.1f ? hipHeight / modelHipHeight : 1f;

            running = true;
            // A session step needs ~600 KiB of stack: ask for 2 MiB rather than the platform default.
            worker = new Thread(Work, 2 * 1024 * 1024) { IsBackground = true, Name = "Duolando follower" };
            worker.Start();
        }

        void Update()
        {
            if (workerFailed) { workerFailed = false; Debug.LogError("Duolando sample: " + Error); }
            if (!running) return;
            // 30 leader frames per second of game time.
            clock += Time.deltaTime;
            int frames = (int)(clock * 30.0);
            if (frames > 0)
            {
                clock -= frames / 30.0;
                Interlocked.Add(ref due, Math.Min(frames, 4));     // skip, not queue, after a long hitch
                wake.Set();
            }
            bool got;
            lock (gate)
            {
                got = fresh;
                if (got) { applying = newest; fresh = false; }
            }
            if (got) Apply(ref applying);
        }

        // Worker thread: the only thread that touches the session.
        void Work()
        {
            LeaderFrame frame = default(LeaderFrame);
            FollowerFrame pulled = default(FollowerFrame);
            int next = 0;
            try
            {
                while (running)
                {
                    wake.WaitOne(100);
                    while (running && Interlocked.CompareExchange(ref due, 0, 0) > 0)
                    {
                        Interlocked.Decrement(ref due);
                        if (next == leaderFrames)
                        {
                            if (!loop) { running = false; break; }
                            session.Reset(seed);                  // drops the music track
                            session.SetMusicTrack(music);
                            next = 0;
                            Interlocked.Increment(ref restarts);
                        }
                        int o = next * J * 3;
                        for (int j = 0; j < J; j++)
                            frame.Set(j, leader[o + 3 * j], leader[o + 3 * j + 1], leader[o + 3 * j + 2]);
                        DuoResult r = session.PushLeader(ref frame);
                        if (r == DuoResult.Backlog) { next = leaderFrames; continue; }   // past the music track's end: start over
                        if (r != DuoResult.Ok && r != DuoResult.NonFiniteInput)
                            throw new DuolandoException(r, "PushLeader");
                        next++;
                        bool any = false;
                        while (session.TryPull(ref pulled)) any = true;
                        if (any)
                        {
                            pulled.ConvertFromSmplX(Coords.Unity);
                            lock (gate) { newest = pulled; fresh = true; }
                        }
                    }
                }
            }
            catch (Exception e)
            {
                running = false;
                Error = e.Message;
                workerFailed = true;
            }
        }

        /// <summary>World rotations (Unity axes) of a converted frame: G[j] = G[parent] * local[j].</summary>
        public static void WorldRotations(ref FollowerFrame f, Quaternion[] g)
        {
            for (int j = 0; j < J; j++)
            {
                Quat q = f.LocalRotation(j);
                Quaternion local = new Quaternion(q.X, q.Y, q.Z, q.W);
                g[j] = Parent[j] < 0 ? local : g[Parent[j]] * local;
            }
        }

        void Apply(ref FollowerFrame f)
        {
            WorldRotations(ref f, world);
            Quaternion character = follower.transform.rotation;
            for (int j = 0; j < J; j++)
                if (bones[j] != null) bones[j].rotation = character * world[j] * rest[j];
            Vec3 root = f.Root;
            bones[0].position = follower.transform.TransformPoint(new Vector3(root.X, root.Y, root.Z) * positionScale);
            FramesApplied++;
        }

        void OnDestroy()
        {
            running = false;
            wake.Set();
            if (worker != null) worker.Join();
            if (session != null) session.Dispose();
            if (model != null) model.Dispose();
            session = null;
            model = null;
        }

        void Fail(string message)
        {
            Error = message;
            Debug.LogError("Duolando sample: " + message);
        }

        // StreamingAssets: a plain file on desktop and iOS, inside the APK on Android.
        IEnumerator Load(string name, Action<byte[]> done)
        {
            string path = Path.Combine(Application.streamingAssetsPath, name);
#if UNITY_ANDROID && !UNITY_EDITOR
            using (UnityWebRequest req = UnityWebRequest.Get(path))
            {
                yield return req.SendWebRequest();
                if (req.result != UnityWebRequest.Result.Success) { Fail(path + ": " + req.error); yield break; }
                done(req.downloadHandler.data);
            }
#else
            try { done(File.ReadAllBytes(path)); }
            catch (Exception e) { Fail(path + ": " + e.Message); }
            yield break;
#endif
        }
    }

    /// <summary>Reads a 2-D little-endian float32 C-order .npy file (numpy format 1.0-3.0).</summary>
    public static class Npy
    {
        public static float[] ReadFloat32(byte[] b, out int rows, out int cols)
        {
            if (b.Length < 10 || b[0] != 0x93 || b[1] != (byte)'N' || b[2] != (byte)'U' || b[3] != (byte)'M'
                || b[4] != (byte)'P' || b[5] != (byte)'Y')
                throw new InvalidDataException("not a .npy file");
            int major = b[6];
            int headerLen, offset;
            if (major == 1) { headerLen = b[8] | (b[9] << 8); offset = 10; }
            else
            {
                if (b.Length < 12) throw new InvalidDataException("truncated .npy header");
                headerLen = b[8] | (b[9] << 8) | (b[10] << 16) | (b[11] << 24);
                offset = 12;
            }
            if (headerLen < 0 || offset + headerLen > b.Length) throw new InvalidDataException("truncated .npy header");
            string header = System.Text.Encoding.ASCII.GetString(b, offset, headerLen);
            if (!header.Contains("'descr': '<f4'") || !header.Contains("'fortran_order': False"))
                throw new InvalidDataException(".npy is not C-order little-endian float32: " + header);
            int open = header.IndexOf('(', header.IndexOf("'shape'", StringComparison.Ordinal));
            int close = header.IndexOf(')', open);
            string[] dims = header.Substring(open + 1, close - open - 1).Split(new[] { ',' }, StringSplitOptions.RemoveEmptyEntries);
            if (dims.Length != 2) throw new InvalidDataException(".npy is not 2-D: " + header);
            rows = int.Parse(dims[0].Trim());
            cols = int.Parse(dims[1].Trim());
            int data = offset + headerLen;
            long n = (long)rows * cols;
            if (rows < 0 || cols < 0 || data + n * 4 != b.Length) throw new InvalidDataException(".npy size does not match its shape");
            float[] values = new float[n];
            Buffer.BlockCopy(b, data, values, 0, (int)(n * 4));
            if (!BitConverter.IsLittleEndian) throw new PlatformNotSupportedException("big-endian host");
            return values;
        }
    }
}

// Duolando.cs — C# P/Invoke wrapper of libduolando (include/duolando.h) for
// Unity (Mono and IL2CPP; desktop, Android arm64 / Quest) and plain .NET.
//
// - Handles are SafeHandles: a forgotten Dispose still frees native memory.
// - Frames are blittable structs passed by ref: no managed allocation per
//   frame (needs "Allow unsafe code", set by Duolando.asmdef).
// - No callbacks cross the boundary (nothing needs MonoPInvokeCallback).
// - Thread rules (from the header): a Model may be used from any number of
//   threads; a Session from one thread at a time. Run PushLeader on a
//   worker thread (it runs the model), not on Unity's main thread.
// - Two model families (Model.Family): Duolando (a follower: Session,
//   leader frames in, FollowerFrame out) and Bailando (a solo dancer to
//   music: SoloSession, music rows in, 24 joint positions out; its
//   TryPullPositions runs the model: a worker thread too). The
//   Duolando-only calls on a solo model (PushLeader, TryPull, SeedTokens,
//   StepBatch) throw DuolandoException with the library's message. A third,
//   Transflower (a probabilistic solo dancer: TransflowerSession, audio rows
//   in, motion features out; TransflowerStepBatch steps several sessions
//   through one step's memory).
// - Expected outcomes (NonFiniteInput, Backlog, NotReady) are returned as
//   DuoResult values; anything else throws DuolandoException with the
//   library's message.
using System;
using System.Runtime.InteropServices;
using System.Text;

namespace Duolando
{
    public enum DuoResult : int
    {
        Ok = 0,
        NullParameter = 1,
        InvalidArgument = 2,
        BadModel = 3,
        BufferTooSmall = 4,
        NotReady = 5,
        NonFiniteInput = 6,
        Backlog = 7,
        Io = 8,
        Panic = 9,
        Internal = 10,
        Ended = 11,
    }

    public enum Coords : uint
    {
        SmplX = 0,
        Unity = 1,
        Unreal = 2,
    }

    public enum SamplingMode : uint
    {
        Greedy = 0,
        TopK = 1,
        /// <summary>Among the TopK best, by softmax(logits / (TemperatureMilli / 1000)).</summary>
        Softmax = 2,
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct Vec3
    {
        public float X, Y, Z;
        public Vec3(float x, float y, float z) { X = x; Y = y; Z = z; }
#if UNITY_5_3_OR_NEWER
        public UnityEngine.Vector3 ToVector3() { return new UnityEngine.Vector3(X, Y, Z); }
#endif
    }

    [StructLayout(LayoutKind.Sequential)]
    public struct Quat
    {
        public float X, Y, Z, W;
#if UNITY_5_3_OR_NEWER
        public UnityEngine.Quaternion ToQuaternion() { return new UnityEngine.Quaternion(X, Y, Z, W); }
#endif
    }

    /// <summary>duo_leader_frame: 55 joints x (x, y, z), 660 bytes.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public unsafe struct LeaderFrame
    {
        public const int Joints = 55;
        public fixed float Xyz[Joints * 3];

        public void Set(int joint, float x, float y, float z)
        {
            if ((uint)joint >= Joints) throw new ArgumentOutOfRangeException("joint");
            fixed (float* p = Xyz)
            {
                p[3 * joint] = x;
                p[3 * joint + 1] = y;
                p[3 * joint + 2] = z;
            }
        }
#if UNITY_5_3_OR_NEWER
        public void Set(int joint, UnityEngine.Vector3 p) { Set(joint, p.x, p.y, p.z); }
#endif
        /// <summary>Converts in place from `from` (e.g. Coords.Unity) to SMPL-X, ready to push.</summary>
        public void ConvertToSmplX(Coords from)
        {
            Native.Check(Native.duo_leader_frame_convert(ref this, (uint)from));
        }
    }

    /// <summary>duo_follower_frame: 1560 bytes.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public unsafe struct FollowerFrame
    {
        public const int Joints = 55;
        public ulong Index;
        public fixed float Positions[Joints * 3];
        public fixed float Rotations[Joints * 4];
        public Vec3 Root;

        public Vec3 Position(int joint)
        {
            if ((uint)joint >= Joints) throw new ArgumentOutOfRangeException("joint");
            fixed (float* p = Positions) return new Vec3(p[3 * joint], p[3 * joint + 1], p[3 * joint + 2]);
        }

        public Quat LocalRotation(int joint)
        {
            if ((uint)joint >= Joints) throw new ArgumentOutOfRangeException("joint");
            Quat q;
            fixed (float* p = Rotations)
            {
                q.X = p[4 * joint];
                q.Y = p[4 * joint + 1];
                q.Z = p[4 * joint + 2];
                q.W = p[4 * joint + 3];
            }
            return q;
        }

        /// <summary>Converts in place from SMPL-X to `to` (e.g. Coords.Unity).</summary>
        public void ConvertFromSmplX(Coords to)
        {
            Native.Check(Native.duo_follower_frame_convert(ref this, (uint)to));
        }
    }

    /// <summary>duo_model_info.family (DUO_FAMILY_*).</summary>
    public enum ModelFamily : uint
    {
        /// <summary>A follower dancing with a leader (55 SMPL-X joints, 30 fps): Session.</summary>
        Duolando = 0,
        /// <summary>A solo dancer to music (24 SMPL joints, 60 fps): SoloSession.</summary>
        Bailando = 1,
        /// <summary>A probabilistic solo dancer (motion features from audio features, 20 fps):
        /// TransflowerSession.</summary>
        Transflower = 2,
    }

    /// <summary>duo_transflower_info (48 bytes).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct TransflowerInfo
    {
        /// <summary>Floats per frame (the model's scaled motion features).</summary>
        public uint Channels;
        /// <summary>Rows of the motion seed (SeedRows x Channels floats).</summary>
        public uint SeedRows;
        public uint Inputs;
        /// <summary>Floats per audio row (PushAudio).</summary>
        public uint AudioFeatures;
        /// <summary>Audio rows a step reads.</summary>
        public uint AudioWindow;
        /// <summary>Style labels a session takes, and values of the first.</summary>
        public uint Labels, LabelValues;
        /// <summary>Floats of one base sample (TryPullFrame with noise).</summary>
        public uint NoiseFloats;
        public uint Fps;
        /// <summary>Frame t is song row OutputTimeOffset + t.</summary>
        public uint OutputTimeOffset;
        /// <summary>Audio rows after a frame's own row its step reads (19: 0.95 s).</summary>
        public int LookaheadRows;
        public uint Reserved;
    }

    /// <summary>duo_transflower_config (32 bytes): start from TransflowerSession.Preset.</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct TransflowerConfig
    {
        /// <summary>Steps between recomputations of every row (1 = the offline model).</summary>
        public uint Refresh;
        public KvType Kv;
        public uint InputBufferRows, PendingFrames;
        /// <summary>1: a share of the rows recomputed every step (flat cost); 0: all every Refresh-th step.</summary>
        public uint Rolling;
        /// <summary>1: a session for step batches only (TransflowerStepBatch.Step makes its frames,
        /// TryPullFrame takes them; it holds its state alone, no step memory); 0: its pulls step it.</summary>
        public uint Batched;
        /// <summary>The base samples' seed: another seed, another dance.</summary>
        public ulong RngSeed;
    }

    /// <summary>duo_model_info (32 bytes).</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct ModelInfo
    {
        /// <summary>Joints per pose (55; Bailando 24).</summary>
        public uint Joints;
        /// <summary>Floats per music frame (54; Bailando 438, one row per token).</summary>
        public uint MusicFeatures;
        /// <summary>Motion frames per second (30; Bailando 60).</summary>
        public uint Fps;
        /// <summary>Motion frames per token (4; Bailando 8).</summary>
        public uint FramesPerToken;
        public uint BlockSize, LookForward, Mapped;
        /// <summary>The model family (a ModelFamily value; 0 = Duolando).</summary>
        public ModelFamily Family;
    }

    public enum KvType : uint
    {
        F32 = 0,
        F16 = 1,
    }

    /// <summary>duo_session_config (64 bytes). Start from Model.MinimumConfig() / ReferenceConfig().</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct SessionConfig
    {
        public uint Lookahead, EncFuture, DecFuture, Shift, MusicLookahead, LatPast, PendingFrames, MusicBufferFrames;
        public SamplingMode Sampling;
        public uint TopK;
        /// <summary>GPT cache schedule: 2 (every preset's) two caches, the next window filled ahead (no step re-prefills a window);
        /// 0 one cache re-filled at each window jump (least memory, a costly step every chunk); 1 one cache per live window.</summary>
        public uint Staggered;
        public KvType Kv;
        public ulong RngSeed;
        /// <summary>SamplingMode.Softmax's temperature in thousandths, 1..100000.</summary>
        public uint TemperatureMilli;
        /// <summary>0.</summary>
        public uint Reserved;
    }

    public sealed class DuolandoException : Exception
    {
        public readonly DuoResult Result;
        public DuolandoException(DuoResult result, string message) : base(result + ": " + message) { Result = result; }
    }

    public sealed class ModelHandle : SafeHandle
    {
        public ModelHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }
        protected override bool ReleaseHandle() { Native.duo_model_free(handle); return true; }
    }

    public sealed class SessionHandle : SafeHandle
    {
        public SessionHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }
        protected override bool ReleaseHandle() { Native.duo_session_free(handle); return true; }
    }

    public sealed class StepBatchHandle : SafeHandle
    {
        /// <summary>Unmanaged memory the batch was placed in (_new_in), freed after it; or zero.</summary>
        internal IntPtr Memory;
        public StepBatchHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }
        protected override bool ReleaseHandle()
        {
            Native.duo_step_batch_free(handle);
            if (Memory != IntPtr.Zero) Marshal.FreeHGlobal(Memory);
            Memory = IntPtr.Zero;
            return true;
        }
    }

    /// <summary>Unmanaged memory owned by a SafeHandle (music tracks and model copies the library borrows).</summary>
    public sealed class NativeBuffer : SafeHandle
    {
        public readonly long Bytes;
        public NativeBuffer(long bytes) : base(IntPtr.Zero, true)
        {
            SetHandle(Marshal.AllocHGlobal(new IntPtr(bytes)));
            Bytes = bytes;
        }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }
        protected override bool ReleaseHandle() { Marshal.FreeHGlobal(handle); return true; }
    }

    internal static unsafe class Native
    {
#if UNITY_IOS && !UNITY_EDITOR
        const string Lib = "__Internal";
#else
        const string Lib = "duolando";
#endif
        const CallingConvention CC = CallingConvention.Cdecl;

        [DllImport(Lib, CallingConvention = CC)] public static extern IntPtr duo_version();
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_set_threads(uint threads);
        [DllImport(Lib, CallingConvention = CC)] public static extern uint duo_get_threads();
        [DllImport(Lib, CallingConvention = CC)] public static extern UIntPtr duo_last_error_message(byte[] buf, UIntPtr len);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_model_open_file(byte[] pathUtf8Nul, out ModelHandle model);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_model_open_copy(byte[] bytes, UIntPtr len, out ModelHandle model);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_model_get_info(ModelHandle model, out ModelInfo info);
        [DllImport(Lib, CallingConvention = CC)] public static extern void duo_model_free(IntPtr model);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_model_seed_tokens(ModelHandle model, float[] follower, float[] leader, UIntPtr frames, [Out] uint[] tokens);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_config_minimum(ModelHandle model, out SessionConfig config);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_config_reference(ModelHandle model, out SessionConfig config);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_config_preset(ModelHandle model, byte[] nameUtf8Nul, out SessionConfig config);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_new(ModelHandle model, ref SessionConfig config, uint[] seed, out SessionHandle session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_new_batched(ModelHandle model, ref SessionConfig config, uint[] seed, StepBatchHandle batch, out SessionHandle session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_latency_frames(SessionHandle session, out uint frames);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_set_music_track(SessionHandle session, NativeBuffer track, UIntPtr floats);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_set_music_track(SessionHandle session, float* track, UIntPtr floats);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_push_music(SessionHandle session, float[] features, UIntPtr n);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_push_music(SessionHandle session, float* features, UIntPtr n);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_finish(SessionHandle session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_pull_positions(SessionHandle session, float* positions, UIntPtr n, out ulong index);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_push_leader(SessionHandle session, ref LeaderFrame frame);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_pull_follower(SessionHandle session, ref FollowerFrame frame);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_reset(SessionHandle session, uint[] seed);
        [DllImport(Lib, CallingConvention = CC)] public static extern void duo_session_free(IntPtr session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_get_info(ModelHandle model, out TransflowerInfo info);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_config_preset(ModelHandle model, byte[] nameUtf8Nul, out TransflowerConfig config);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_session_new(ModelHandle model, ref TransflowerConfig config, float[] seed, UIntPtr n, uint[] labels, UIntPtr nLabels, out SessionHandle session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_pull_frame(SessionHandle session, float* frame, UIntPtr n, out ulong index);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_pull_frame_with_noise(SessionHandle session, float[] noise, UIntPtr nNoise, float* frame, UIntPtr n, out ulong index);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_session_reset(SessionHandle session, ulong rngSeed);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_step_batch_new(ModelHandle model, ref SessionConfig config, UIntPtr maxSessions, out StepBatchHandle batch);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_step_batch_push_leader(StepBatchHandle batch, IntPtr[] sessions, [In] LeaderFrame[] frames, UIntPtr n, out UIntPtr failedSession);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_step_batch_bytes(ModelHandle model, out UIntPtr bytes);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_step_batch_new(ModelHandle model, out StepBatchHandle batch);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_transflower_step_batch_new_in(ModelHandle model, IntPtr memory, UIntPtr len, out StepBatchHandle batch);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_step_batch_step(StepBatchHandle batch, IntPtr[] sessions, UIntPtr n, out UIntPtr stepped, out UIntPtr failedSession);
        [DllImport(Lib, CallingConvention = CC)] public static extern void duo_step_batch_free(IntPtr batch);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_leader_frame_convert(ref LeaderFrame frame, uint coords);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_follower_frame_convert(ref FollowerFrame frame, uint coords);
        [DllImport(Lib, CallingConvention = CC)] public static extern Vec3 duo_vec3_to_unity(Vec3 v);
        [DllImport(Lib, CallingConvention = CC)] public static extern Vec3 duo_vec3_to_unreal(Vec3 v);

        public static string LastError()
        {
            ulong n = (ulong)duo_last_error_message(null, UIntPtr.Zero);
            if (n == 0) return "";
            byte[] buf = new byte[n + 1];
            duo_last_error_message(buf, new UIntPtr((ulong)buf.Length));
            return Encoding.UTF8.GetString(buf, 0, (int)n);
        }

        public static void Check(DuoResult r)
        {
            if (r != DuoResult.Ok) throw new DuolandoException(r, LastError());
        }
    }

    /// <summary>An opened model. Thread-safe; share one between sessions.</summary>
    public sealed class Model : IDisposable
    {
        internal readonly ModelHandle Handle;

        Model(ModelHandle h) { Handle = h; }

        public static string Version { get { return Marshal.PtrToStringAnsi(Native.duo_version()); } }

        /// <summary>Threads the large matrix products of every session are split over
        /// (the calling thread plus pooled workers; 1 = the calling thread only, the default).
        /// Outputs do not depend on it. Process-wide.</summary>
        public static uint Threads
        {
            get { return Native.duo_get_threads(); }
            set { Native.Check(Native.duo_set_threads(value)); }
        }

        /// <summary>Memory-maps a .duo file (on Android, copy it out of the APK to persistentDataPath first).</summary>
        public static Model OpenFile(string path)
        {
            ModelHandle h;
            byte[] utf8 = Encoding.UTF8.GetBytes(path + "\0");
            Native.Check(Native.duo_model_open_file(utf8, out h));
            return new Model(h);
        }

        /// <summary>Copies .duo bytes (e.g. TextAsset.bytes) into library memory.</summary>
        public static Model OpenCopy(byte[] bytes)
        {
            ModelHandle h;
            Native.Check(Native.duo_model_open_copy(bytes, new UIntPtr((ulong)bytes.LongLength), out h));
            return new Model(h);
        }

        public ModelInfo Info
        {
            get { ModelInfo i; Native.Check(Native.duo_model_get_info(Handle, out i)); return i; }
        }

        /// <summary>Duolando (a follower: Session) or Bailando (a solo dancer to music: SoloSession).</summary>
        public ModelFamily Family { get { return Info.Family; } }

        /// <summary>True for a solo model (Bailando): music rows in, positions out (SoloSession).</summary>
        public bool IsSolo { get { return Info.Family == ModelFamily.Bailando; } }

        /// <summary>Seed tokens a session of this model takes: 5 (Duolando: up, down, lhand, rhand,
        /// transl) or 2 (Bailando: up, down).</summary>
        public int SeedTokenCount { get { return IsSolo ? 2 : 5; } }

        /// <summary>A named budget (duo_session_config_preset). Duolando: "reference", "interactive",
        /// "live-music", "minimum"; Bailando: "exact" (the offline model's numbers), "reference",
        /// "interactive", "minimum". Another name throws (InvalidArgument, with the list).</summary>
        public SessionConfig Preset(string name)
        {
            if (name == null) throw new ArgumentNullException("name");
            SessionConfig c;
            Native.Check(Native.duo_session_config_preset(Handle, Encoding.UTF8.GetBytes(name + "\0"), out c));
            return c;
        }

        public SessionConfig MinimumConfig()
        {
            SessionConfig c; Native.Check(Native.duo_session_config_minimum(Handle, out c)); return c;
        }

        public SessionConfig ReferenceConfig()
        {
            SessionConfig c; Native.Check(Native.duo_session_config_reference(Handle, out c)); return c;
        }

        /// <summary>Seed tokens from follower and leader start frames (frames x 165 floats each, SMPL-X).
        /// Duolando only: a solo model throws (its sessions take their 2 seed tokens directly).</summary>
        public uint[] SeedTokens(float[] followerPos3d, float[] leaderPos3d)
        {
            if (followerPos3d.Length != leaderPos3d.Length || followerPos3d.Length % 165 != 0)
                throw new ArgumentException("follower and leader need the same whole number of 165-float frames");
            uint[] t = new uint[5];
            Native.Check(Native.duo_model_seed_tokens(Handle, followerPos3d, leaderPos3d, new UIntPtr((ulong)(followerPos3d.Length / 165)), t));
            return t;
        }

        /// <summary>Releases this reference (sessions keep the weights alive until they are disposed).</summary>
        public void Dispose() { Handle.Dispose(); }
    }

    /// <summary>What Session (a follower) and SoloSession (a solo dancer) share: the native
    /// session, its latency, music, Finish, positions, Reset, Dispose. One thread at a time.</summary>
    public abstract class SessionBase : IDisposable
    {
        internal readonly SessionHandle handle;
        NativeBuffer track;

        /// <summary>The model family of this session.</summary>
        public readonly ModelFamily Family;
        /// <summary>Joints per frame (55; solo 24): TryPullPositions writes Joints x 3 floats.</summary>
        public readonly int Joints;
        /// <summary>Floats per music frame (54; solo 438 per row).</summary>
        public readonly int MusicFeatures;
        /// <summary>Motion frames per second (30; solo 60).</summary>
        public readonly int Fps;
        /// <summary>Seed tokens this session takes (5; solo 2).</summary>
        public readonly int SeedTokenCount;

        internal SessionBase(Model model, SessionConfig config, uint[] seedTokens, StepBatch batch = null)
        {
            if (model == null) throw new ArgumentNullException("model");
            ModelInfo info = model.Info;
            Family = info.Family;
            Joints = (int)info.Joints;
            MusicFeatures = (int)info.MusicFeatures;
            Fps = (int)info.Fps;
            SeedTokenCount = model.SeedTokenCount;
            CheckSeed(seedTokens);
            if (batch == null)
                Native.Check(Native.duo_session_new(model.Handle, ref config, seedTokens, out handle));
            else
                Native.Check(Native.duo_session_new_batched(model.Handle, ref config, seedTokens, batch.Handle, out handle));
        }

        // The library reads as many tokens as the family takes: never fewer in the array.
        void CheckSeed(uint[] seedTokens)
        {
            if (seedTokens == null || seedTokens.Length != SeedTokenCount)
                throw new ArgumentException(SeedTokenCount + " seed tokens for a " + Family + " model", "seedTokens");
        }

        /// <summary>Frames between the input that makes a frame final and that frame (duo_session_latency_frames).</summary>
        public uint LatencyFrames
        {
            get { uint n; Native.Check(Native.duo_session_latency_frames(handle, out n)); return n; }
        }

        /// <summary>The whole music track, before any music is pushed: Duolando frames x 54 floats
        /// (copied to native memory the session reads); solo rows x 438 floats (copied into the
        /// session: its config's MusicBufferFrames must hold them all).</summary>
        public unsafe void SetMusicTrack(float[] features)
        {
            if (features == null) throw new ArgumentNullException("features");
            if (Family == ModelFamily.Bailando)
            {
                fixed (float* p = features)
                    Native.Check(Native.duo_session_set_music_track(handle, p, new UIntPtr((ulong)features.LongLength)));
                if (track != null) { track.Dispose(); track = null; }
                return;
            }
            NativeBuffer b = new NativeBuffer(4L * features.LongLength);
            Marshal.Copy(features, 0, b.DangerousGetHandle(), features.Length);
            DuoResult r = Native.duo_session_set_music_track(handle, b, new UIntPtr((ulong)features.LongLength));
            if (r != DuoResult.Ok) { b.Dispose(); Native.Check(r); }
            if (track != null) track.Dispose();
            track = b;
        }

        /// <summary>One music frame (Duolando: 54 floats), or one or more whole rows (solo: n x 438
        /// floats, one row per token). Ok, NonFiniteInput (session unchanged) or Backlog (the music
        /// buffer is full: pull first); throws on anything else.</summary>
        public DuoResult PushMusic(float[] features)
        {
            if (features == null) throw new ArgumentNullException("features");
            return PushMusic(features, 0, features.Length);
        }

        /// <summary>As PushMusic(float[]) with `count` floats of `features` from `offset` (no copy:
        /// push rows straight out of a whole track).</summary>
        public unsafe DuoResult PushMusic(float[] features, int offset, int count)
        {
            if (features == null) throw new ArgumentNullException("features");
            if (offset < 0 || count < 0 || offset > features.Length - count) throw new ArgumentOutOfRangeException("count");
            DuoResult r;
            fixed (float* p = features)
                r = Native.duo_session_push_music(handle, count == 0 ? null : p + offset, new UIntPtr((ulong)count));
            if (r != DuoResult.Ok && r != DuoResult.NonFiniteInput && r != DuoResult.Backlog) Native.Check(r);
            return r;
        }

        /// <summary>The input has ended (duo_session_finish): a follower decodes what its look-ahead
        /// allows; a solo dancer pads the music as the authors' demo does and dances to its end.
        /// Pull the remaining frames as usual. Until Reset, PushLeader answers Ended. Again: nothing.
        /// A solo session throws before any music row.</summary>
        public void Finish()
        {
            Native.Check(Native.duo_session_finish(handle));
        }

        /// <summary>True and `positions[0 .. Joints x 3)` written (world joint positions, metres,
        /// SMPL-X axes; Positions.Convert for Unity or Unreal) with the frame's index when a frame is
        /// ready; false when none is. Any family. On a solo session this runs the model steps the
        /// frame needs (the costly call: a worker thread).</summary>
        public bool TryPullPositions(float[] positions, out ulong index)
        {
            return TryPullPositions(positions, 0, out index);
        }

        /// <summary>As TryPullPositions(float[], out ulong), written from `offset` (e.g. frame i of a
        /// whole clip at i x Joints x 3).</summary>
        public unsafe bool TryPullPositions(float[] positions, int offset, out ulong index)
        {
            if (positions == null) throw new ArgumentNullException("positions");
            int n = Joints * 3;
            if (offset < 0 || offset > positions.Length - n)
                throw new ArgumentException("positions needs " + n + " floats (" + Joints + " joints x 3) from offset " + offset, "positions");
            DuoResult r;
            fixed (float* p = positions)
                r = Native.duo_session_pull_positions(handle, p + offset, new UIntPtr((ulong)n), out index);
            if (r == DuoResult.NotReady) return false;
            Native.Check(r);
            return true;
        }

        /// <summary>Back to frame 0 with new seed tokens (5, or 2 for a solo model; the music track is dropped).</summary>
        public void Reset(uint[] seedTokens)
        {
            CheckSeed(seedTokens);
            Native.Check(Native.duo_session_reset(handle, seedTokens));
            if (track != null) { track.Dispose(); track = null; }
        }

        public void Dispose()
        {
            handle.Dispose();   // first: the session borrows the track
            if (track != null) track.Dispose();
            track = null;
        }
    }

    /// <summary>One follower dancer (a Duolando model). One thread at a time. On a solo model it
    /// takes 2 seed tokens and PushLeader / TryPull throw (use SoloSession).</summary>
    public sealed class Session : SessionBase
    {
        public Session(Model model, SessionConfig config, uint[] seedTokens) : base(model, config, seedTokens) { }

        /// <summary>A session bound to `batch` (duo_session_new_batched): it holds its state alone
        /// (1.5 MB less at full size) and borrows the batch's step memory for each of its calls,
        /// which then run one at a time across the sessions bound to that batch (any threads).
        /// Same frames as a session of the other constructor. The native batch lives until its
        /// last bound session is disposed.</summary>
        public Session(Model model, SessionConfig config, uint[] seedTokens, StepBatch batch)
            : base(model, config, seedTokens, RequireBatch(batch)) { }

        static StepBatch RequireBatch(StepBatch batch)
        {
            if (batch == null) throw new ArgumentNullException("batch");
            return batch;
        }

        /// <summary>Ok, NonFiniteInput (rejected, session unchanged: push your last good frame) or Backlog (pull first).</summary>
        public DuoResult PushLeader(ref LeaderFrame frame)
        {
            DuoResult r = Native.duo_session_push_leader(handle, ref frame);
            if (r != DuoResult.Ok && r != DuoResult.NonFiniteInput && r != DuoResult.Backlog) Native.Check(r);
            return r;
        }

        /// <summary>True and `frame` written when a follower frame is ready.</summary>
        public bool TryPull(ref FollowerFrame frame)
        {
            DuoResult r = Native.duo_session_pull_follower(handle, ref frame);
            if (r == DuoResult.NotReady) return false;
            Native.Check(r);
            return true;
        }
    }

    /// <summary>One solo dancer to music (a Bailando model: Model.IsSolo). Seed: 2 tokens (up,
    /// down). Push music rows (438 floats each, one per token: 7.5 rows per second) with
    /// PushMusic, or give them all with SetMusicTrack; pull frames (24 joints x 3 floats, 60 fps)
    /// with TryPullPositions, which runs the model (a worker thread, not Unity's main thread);
    /// Finish at the end of the music, then pull the last frames. One thread at a time.</summary>
    public sealed class SoloSession : SessionBase
    {
        /// <summary>Joints of a solo frame (SMPL: 0-21 as SMPL-X's, 22 left_hand, 23 right_hand).</summary>
        public const int SoloJoints = 24;

        public SoloSession(Model model, SessionConfig config, uint[] seedTokens) : base(RequireSolo(model), config, seedTokens) { }

        static Model RequireSolo(Model model)
        {
            if (model == null) throw new ArgumentNullException("model");
            if (!model.IsSolo)
                throw new ArgumentException("SoloSession needs a solo model (family Bailando); this is a " + model.Family + " model: use Session", "model");
            return model;
        }
    }

    /// <summary>A Transflower dancer: audio feature rows in (PushAudio, pushed
    /// Info.LookaheadRows ahead), the model's motion features out (TryPullFrame, Channels
    /// floats each, scaled), from a motion seed, style labels and a seed for its base
    /// samples (another seed, another dance). Preset "exact" gives the offline model's frames;
    /// "reference" and "realtime" are faster approximations. One thread at a time.</summary>
    public sealed class TransflowerSession : IDisposable
    {
        internal readonly SessionHandle handle;
        /// <summary>The model's sizes (duo_transflower_get_info).</summary>
        public readonly TransflowerInfo Info;

        /// <summary>A named configuration: "exact", "reference" or "realtime" (another throws).</summary>
        public static TransflowerConfig Preset(Model model, string name)
        {
            if (model == null) throw new ArgumentNullException("model");
            if (name == null) throw new ArgumentNullException("name");
            TransflowerConfig c;
            Native.Check(Native.duo_transflower_config_preset(model.Handle, Encoding.UTF8.GetBytes(name + "\0"), out c));
            return c;
        }

        /// <summary>seedMotion: Info.SeedRows x Info.Channels floats; labels: Info.Labels values
        /// (an empty array when the model takes none).</summary>
        public TransflowerSession(Model model, TransflowerConfig config, float[] seedMotion, uint[] labels)
        {
            if (model == null) throw new ArgumentNullException("model");
            if (model.Family != ModelFamily.Transflower)
                throw new ArgumentException("TransflowerSession needs a Transflower model; this is a " + model.Family + " model", "model");
            if (seedMotion == null) throw new ArgumentNullException("seedMotion");
            if (labels == null) labels = new uint[0];
            Native.Check(Native.duo_transflower_get_info(model.Handle, out Info));
            Native.Check(Native.duo_transflower_session_new(model.Handle, ref config, seedMotion, new UIntPtr((ulong)seedMotion.LongLength),
                labels.Length == 0 ? null : labels, new UIntPtr((ulong)labels.LongLength), out handle));
        }

        /// <summary>One or more whole audio rows (Info.AudioFeatures floats each).</summary>
        public unsafe void PushAudio(float[] rows)
        {
            if (rows == null) throw new ArgumentNullException("rows");
            fixed (float* p = rows)
                Native.Check(Native.duo_session_push_music(handle, p, new UIntPtr((ulong)rows.LongLength)));
        }

        /// <summary>The next frame into `frame` (Info.Channels floats), running its step (the
        /// costly call: off the main thread); false while its audio is not in yet. A frame a
        /// TransflowerStepBatch made is taken without a step (a Batched session never steps here:
        /// false until its batch has made one).
        /// `noise`: the step's base sample (Info.NoiseFloats), or null for the session's RNG.</summary>
        public unsafe bool TryPullFrame(float[] frame, out ulong index, float[] noise = null)
        {
            if (frame == null) throw new ArgumentNullException("frame");
            DuoResult r;
            fixed (float* p = frame)
                r = noise == null
                    ? Native.duo_transflower_pull_frame(handle, p, new UIntPtr((ulong)frame.LongLength), out index)
                    : Native.duo_transflower_pull_frame_with_noise(handle, noise, new UIntPtr((ulong)noise.LongLength), p, new UIntPtr((ulong)frame.LongLength), out index);
            if (r == DuoResult.NotReady) return false;
            Native.Check(r);
            return true;
        }

        /// <summary>Back to the seed motion with no audio; the base samples reseeded.</summary>
        public void Reset(ulong rngSeed) { Native.Check(Native.duo_transflower_session_reset(handle, rngSeed)); }

        public void Dispose() { handle.Dispose(); }
    }

    /// <summary>Joint positions as TryPullPositions writes them (x, y, z per joint, SMPL-X axes).</summary>
    public static class Positions
    {
        /// <summary>Converts `joints` positions from `offset` in place from SMPL-X to `to` (Unity:
        /// (-x, y, z); Unreal: 100 (z, -x, y), centimetres), with the library's conversions.</summary>
        public static void Convert(float[] xyz, int offset, int joints, Coords to)
        {
            if (xyz == null) throw new ArgumentNullException("xyz");
            if (offset < 0 || joints < 0 || offset > xyz.Length - 3 * joints) throw new ArgumentOutOfRangeException("joints");
            if (to != Coords.SmplX && to != Coords.Unity && to != Coords.Unreal) throw new ArgumentOutOfRangeException("to");
            for (int j = 0; j < joints; j++)
            {
                int o = offset + 3 * j;
                Vec3 v = new Vec3(xyz[o], xyz[o + 1], xyz[o + 2]);
                if (to == Coords.Unity) v = Native.duo_vec3_to_unity(v);
                else if (to == Coords.Unreal) v = Native.duo_vec3_to_unreal(v);
                xyz[o] = v.X;
                xyz[o + 1] = v.Y;
                xyz[o + 2] = v.Z;
            }
        }

        /// <summary>Joint j of a positions buffer.</summary>
        public static Vec3 Get(float[] xyz, int offset, int joint)
        {
            int o = offset + 3 * joint;
            return new Vec3(xyz[o], xyz[o + 1], xyz[o + 2]);
        }
    }

    /// <summary>Several sessions of one model stepped together: each weight matrix is read
    /// once for all of them (16 full-size sessions take 4.4-4.6x the time of one).
    /// Every session ends as after its own PushLeader, bit for bit. One thread at a time,
    /// and the sessions of a call are not used elsewhere during it.</summary>
    public sealed class StepBatch : IDisposable
    {
        readonly StepBatchHandle handle;
        readonly IntPtr[] pointers;
        internal StepBatchHandle Handle { get { return handle; } }
        readonly bool[] added;

        /// <summary>Scratch for up to maxSessions (1..64) sessions of `model` whose
        /// configurations need no more than `config`.</summary>
        public StepBatch(Model model, SessionConfig config, int maxSessions)
        {
            if (maxSessions < 1) throw new ArgumentOutOfRangeException("maxSessions");
            Native.Check(Native.duo_step_batch_new(model.Handle, ref config, new UIntPtr((ulong)maxSessions), out handle));
            pointers = new IntPtr[maxSessions];
            added = new bool[maxSessions];
        }

        /// <summary>frames[i] into sessions[i] for every session. Ok; or NonFiniteInput /
        /// Backlog with `failed` = the session whose frame was refused (no session changed;
        /// -1 on Ok); throws on anything else (another model, a session given twice).</summary>
        public DuoResult PushLeader(Session[] sessions, LeaderFrame[] frames, out int failed)
        {
            int n = sessions.Length;
            if (frames.Length != n) throw new ArgumentException("one frame per session");
            if (n > pointers.Length) throw new ArgumentException("more sessions than the batch holds");
            UIntPtr f = UIntPtr.Zero;
            DuoResult r;
            try
            {
                for (int i = 0; i < n; i++)
                {
                    added[i] = false;
                    sessions[i].handle.DangerousAddRef(ref added[i]);
                    pointers[i] = sessions[i].handle.DangerousGetHandle();
                }
                r = Native.duo_step_batch_push_leader(handle, pointers, frames, new UIntPtr((ulong)n), out f);
            }
            finally
            {
                for (int i = 0; i < n; i++)
                {
                    if (added[i]) sessions[i].handle.DangerousRelease();
                    added[i] = false;
                    pointers[i] = IntPtr.Zero;
                }
            }
            ulong fi = f.ToUInt64();
            failed = fi >= (ulong)n ? -1 : (int)fi;
            if (r != DuoResult.Ok && r != DuoResult.NonFiniteInput && r != DuoResult.Backlog) Native.Check(r);
            return r;
        }

        public void Dispose() { handle.Dispose(); }
    }

    /// <summary>A Transflower step batch: one model's step memory (step scratch, the flow's
    /// reverse weights) that several TransflowerSessions of that model share, stepped one after
    /// another by Step: every frame is the one the session makes alone, bit for bit. Sessions made
    /// with TransflowerConfig.Batched = 1 hold their state alone (only a batch makes their frames;
    /// TryPullFrame takes them); Batched = 0 sessions may be stepped both ways. The batch keeps
    /// its model alive. One thread at a time, and the sessions of a Step are not used elsewhere
    /// during it; Step runs the model (off the main thread).</summary>
    public sealed class TransflowerStepBatch : IDisposable
    {
        /// <summary>Most sessions one Step takes (DUO_MAX_BATCH).</summary>
        public const int MaxSessions = 64;
        readonly StepBatchHandle handle;
        readonly IntPtr[] pointers = new IntPtr[MaxSessions];
        readonly bool[] added = new bool[MaxSessions];

        /// <summary>Bytes of a batch of `model` (the same for any sessions of any configuration).</summary>
        public static long Bytes(Model model)
        {
            if (model == null) throw new ArgumentNullException("model");
            UIntPtr n;
            Native.Check(Native.duo_transflower_step_batch_bytes(model.Handle, out n));
            return (long)n.ToUInt64();
        }

        /// <summary>A batch of `model` (a Transflower model; another throws). inPlace: placed in one
        /// block of Bytes(model) unmanaged bytes allocated here and freed with the batch
        /// (duo_transflower_step_batch_new_in); else the library allocates it.</summary>
        public TransflowerStepBatch(Model model, bool inPlace = false)
        {
            if (model == null) throw new ArgumentNullException("model");
            if (!inPlace)
            {
                Native.Check(Native.duo_transflower_step_batch_new(model.Handle, out handle));
                return;
            }
            long bytes = Bytes(model);
            IntPtr memory = Marshal.AllocHGlobal(new IntPtr(bytes));
            DuoResult r = Native.duo_transflower_step_batch_new_in(model.Handle, memory, new UIntPtr((ulong)bytes), out handle);
            if (r != DuoResult.Ok)
            {
                Marshal.FreeHGlobal(memory);
                Native.Check(r);
            }
            handle.Memory = memory;
        }

        /// <summary>One step of every session of `sessions` whose audio is in (at most MaxSessions).
        /// Ok: `stepped` = how many stepped (0 when none had its audio), `failed` = -1. Backlog:
        /// sessions[failed] has its PendingFrames frames made and not pulled; nothing stepped.
        /// Throws on anything else (a session of another model or given twice: DuolandoException
        /// InvalidArgument, with the library's message naming it).</summary>
        public DuoResult Step(TransflowerSession[] sessions, out int stepped, out int failed)
        {
            if (sessions == null) throw new ArgumentNullException("sessions");
            int n = sessions.Length;
            if (n > MaxSessions) throw new ArgumentException("more sessions than a batch steps at once (" + MaxSessions + ")", "sessions");
            for (int i = 0; i < n; i++)
                if (sessions[i] == null) throw new ArgumentNullException("sessions", "sessions[" + i + "] is null");
            UIntPtr s = UIntPtr.Zero, f = UIntPtr.Zero;
            DuoResult r;
            try
            {
                for (int i = 0; i < n; i++)
                {
                    added[i] = false;
                    sessions[i].handle.DangerousAddRef(ref added[i]);
                    pointers[i] = sessions[i].handle.DangerousGetHandle();
                }
                r = Native.duo_step_batch_step(handle, pointers, new UIntPtr((ulong)n), out s, out f);
            }
            finally
            {
                for (int i = 0; i < n; i++)
                {
                    if (added[i]) sessions[i].handle.DangerousRelease();
                    added[i] = false;
                    pointers[i] = IntPtr.Zero;
                }
            }
            ulong fi = f.ToUInt64();
            failed = fi >= (ulong)n ? -1 : (int)fi;
            stepped = r == DuoResult.Ok ? (int)s.ToUInt64() : 0;
            if (r != DuoResult.Ok && r != DuoResult.Backlog) Native.Check(r);
            return r;
        }

        public void Dispose() { handle.Dispose(); }
    }
}

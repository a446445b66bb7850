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

    [StructLayout(LayoutKind.Sequential)]
    public struct ModelInfo
    {
        public uint Joints, MusicFeatures, Fps, FramesPerToken, BlockSize, LookForward, Mapped, Reserved;
    }

    public enum KvType : uint
    {
        F32 = 0,
        F16 = 1,
    }

    /// <summary>duo_session_config (56 bytes). Start from Model.MinimumConfig() / ReferenceConfig().</summary>
    [StructLayout(LayoutKind.Sequential)]
    public struct SessionConfig
    {
        public uint Lookahead, EncFuture, DecFuture, Shift, MusicLookahead, LatPast, PendingFrames, MusicBufferFrames;
        public SamplingMode Sampling;
        public uint TopK;
        public uint Staggered;
        public KvType Kv;
        public ulong RngSeed;
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
        public StepBatchHandle() : base(IntPtr.Zero, true) { }
        public override bool IsInvalid { get { return handle == IntPtr.Zero; } }
        protected override bool ReleaseHandle() { Native.duo_step_batch_free(handle); return true; }
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

    internal static class Native
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
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_new(ModelHandle model, ref SessionConfig config, uint[] seed, out SessionHandle session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_latency_frames(SessionHandle session, out uint frames);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_set_music_track(SessionHandle session, NativeBuffer track, UIntPtr floats);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_push_music(SessionHandle session, float[] features, UIntPtr n);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_push_leader(SessionHandle session, ref LeaderFrame frame);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_pull_follower(SessionHandle session, ref FollowerFrame frame);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_session_reset(SessionHandle session, uint[] seed);
        [DllImport(Lib, CallingConvention = CC)] public static extern void duo_session_free(IntPtr session);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_step_batch_new(ModelHandle model, ref SessionConfig config, UIntPtr maxSessions, out StepBatchHandle batch);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_step_batch_push_leader(StepBatchHandle batch, IntPtr[] sessions, [In] LeaderFrame[] frames, UIntPtr n, out UIntPtr failedSession);
        [DllImport(Lib, CallingConvention = CC)] public static extern void duo_step_batch_free(IntPtr batch);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_leader_frame_convert(ref LeaderFrame frame, uint coords);
        [DllImport(Lib, CallingConvention = CC)] public static extern DuoResult duo_follower_frame_convert(ref FollowerFrame frame, uint coords);

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

        public SessionConfig MinimumConfig()
        {
            SessionConfig c; Native.Check(Native.duo_session_config_minimum(Handle, out c)); return c;
        }

        public SessionConfig ReferenceConfig()
        {
            SessionConfig c; Native.Check(Native.duo_session_config_reference(Handle, out c)); return c;
        }

        /// <summary>Seed tokens from follower and leader start frames (frames x 165 floats each, SMPL-X).</summary>
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

    /// <summary>One follower dancer. One thread at a time.</summary>
    public sealed class Session : IDisposable
    {
        internal readonly SessionHandle handle;
        NativeBuffer track;

        public Session(Model model, SessionConfig config, uint[] seedTokens)
        {
            if (seedTokens == null || seedTokens.Length != 5) throw new ArgumentException("5 seed tokens");
            Native.Check(Native.duo_session_new(model.Handle, ref config, seedTokens, out handle));
        }

        public uint LatencyFrames
        {
            get { uint n; Native.Check(Native.duo_session_latency_frames(handle, out n)); return n; }
        }

        /// <summary>The whole music track (frames x 54 floats), copied to native memory the session reads.</summary>
        public void SetMusicTrack(float[] features)
        {
            NativeBuffer b = new NativeBuffer(4L * features.LongLength);
            Marshal.Copy(features, 0, b.DangerousGetHandle(), features.Length);
            DuoResult r = Native.duo_session_set_music_track(handle, b, new UIntPtr((ulong)features.LongLength));
            if (r != DuoResult.Ok) { b.Dispose(); Native.Check(r); }
            if (track != null) track.Dispose();
            track = b;
        }

        /// <summary>Ok, NonFiniteInput or Backlog (pull first); throws on anything else.</summary>
        public DuoResult PushMusic(float[] features)
        {
            DuoResult r = Native.duo_session_push_music(handle, features, new UIntPtr((ulong)features.Length));
            if (r != DuoResult.Ok && r != DuoResult.NonFiniteInput && r != DuoResult.Backlog) Native.Check(r);
            return r;
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

        /// <summary>Back to frame 0 with new seed tokens (the music track is dropped).</summary>
        public void Reset(uint[] seedTokens)
        {
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

    /// <summary>Several sessions of one model stepped together: each weight matrix is read
    /// once for all of them (16 full-size sessions take 4.4-4.6x the time of one).
    /// Every session ends as after its own PushLeader, bit for bit. One thread at a time,
    /// and the sessions of a call are not used elsewhere during it.</summary>
    public sealed class StepBatch : IDisposable
    {
        readonly StepBatchHandle handle;
        readonly IntPtr[] pointers;
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
}

// TEST STUB — NOT UNITY. A minimal stand-in for the few UnityEngine types
// the Duolando Unity package uses, so that CI (.ci/ffi.sh) can compile the
// package's runtime (with UNITY_5_3_OR_NEWER) and its sample under Mono and
// run the sample against libduolando without Unity. Behaviour is only
// what the test needs: transforms are flat (no hierarchy, no scale),
// coroutines run to completion at once, there is no player loop.
// Never ship this file; it has nothing to do with Unity's real assembly.
using System;
using System.Collections;
using System.Collections.Generic;

namespace UnityEngine
{
    public struct Vector3
    {
        public float x, y, z;
        public Vector3(float x, float y, float z) { this.x = x; this.y = y; this.z = z; }
        public static Vector3 operator +(Vector3 a, Vector3 b) { return new Vector3(a.x + b.x, a.y + b.y, a.z + b.z); }
        public static Vector3 operator -(Vector3 a, Vector3 b) { return new Vector3(a.x - b.x, a.y - b.y, a.z - b.z); }
        public static Vector3 operator *(Vector3 a, float s) { return new Vector3(a.x * s, a.y * s, a.z * s); }
        public override string ToString() { return "(" + x + ", " + y + ", " + z + ")"; }
    }

    public struct Quaternion
    {
        public float x, y, z, w;
        public Quaternion(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
        public static Quaternion identity { get { return new Quaternion(0, 0, 0, 1); } }
        // Hamilton product, as Unity's (x, y, z, w) Quaternion.
        public static Quaternion operator *(Quaternion a, Quaternion b)
        {
            return new Quaternion(
                a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
                a.w * b.y + a.y * b.w + a.z * b.x - a.x * b.z,
                a.w * b.z + a.z * b.w + a.x * b.y - a.y * b.x,
                a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z);
        }
        public static Vector3 operator *(Quaternion q, Vector3 v)
        {
            Quaternion p = q * new Quaternion(v.x, v.y, v.z, 0) * Inverse(q);
            return new Vector3(p.x, p.y, p.z);
        }
        public static Quaternion Inverse(Quaternion q) { return new Quaternion(-q.x, -q.y, -q.z, q.w); }
        public static Quaternion AngleAxis(float degrees, Vector3 axis)
        {
            double h = degrees * Math.PI / 360.0, s = Math.Sin(h);
            return new Quaternion((float)(axis.x * s), (float)(axis.y * s), (float)(axis.z * s), (float)Math.Cos(h));
        }
    }

    public class Object { }

    public class Transform : Object
    {
        public Vector3 position;
        public Quaternion rotation = Quaternion.identity;
        public Vector3 TransformPoint(Vector3 p) { return position + rotation * p; }
        public Vector3 InverseTransformPoint(Vector3 p) { return Quaternion.Inverse(rotation) * (p - position); }
    }

    public class Component : Object
    {
        public Transform transform = new Transform();
    }

    public class Behaviour : Component { public bool enabled = true; }

    public class YieldInstruction { }
    public sealed class Coroutine : YieldInstruction { }

    public class MonoBehaviour : Behaviour
    {
        // Stub: runs the coroutine (and nested IEnumerators) to its end now.
        public Coroutine StartCoroutine(IEnumerator routine)
        {
            while (routine.MoveNext())
            {
                IEnumerator nested = routine.Current as IEnumerator;
                if (nested != null) StartCoroutine(nested);
            }
            return new Coroutine();
        }
    }

    public enum HumanBodyBones
    {
        Hips = 0, LeftUpperLeg = 1, RightUpperLeg = 2, LeftLowerLeg = 3, RightLowerLeg = 4, LeftFoot = 5,
        RightFoot = 6, Spine = 7, Chest = 8, Neck = 9, Head = 10, LeftShoulder = 11, RightShoulder = 12,
        LeftUpperArm = 13, RightUpperArm = 14, LeftLowerArm = 15, RightLowerArm = 16, LeftHand = 17,
        RightHand = 18, LeftToes = 19, RightToes = 20, LeftEye = 21, RightEye = 22, Jaw = 23,
        LeftThumbProximal = 24, LeftThumbIntermediate = 25, LeftThumbDistal = 26,
        LeftIndexProximal = 27, LeftIndexIntermediate = 28, LeftIndexDistal = 29,
        LeftMiddleProximal = 30, LeftMiddleIntermediate = 31, LeftMiddleDistal = 32,
        LeftRingProximal = 33, LeftRingIntermediate = 34, LeftRingDistal = 35,
        LeftLittleProximal = 36, LeftLittleIntermediate = 37, LeftLittleDistal = 38,
        RightThumbProximal = 39, RightThumbIntermediate = 40, RightThumbDistal = 41,
        RightIndexProximal = 42, RightIndexIntermediate = 43, RightIndexDistal = 44,
        RightMiddleProximal = 45, RightMiddleIntermediate = 46, RightMiddleDistal = 47,
        RightRingProximal = 48, RightRingIntermediate = 49, RightRingDistal = 50,
        RightLittleProximal = 51, RightLittleIntermediate = 52, RightLittleDistal = 53,
        UpperChest = 54, LastBone = 55,
    }

    public class Animator : Behaviour
    {
        // Stub only: the test fills in the rig.
        public readonly Dictionary<HumanBodyBones, Transform> StubBones = new Dictionary<HumanBodyBones, Transform>();
        public bool isHuman { get { return StubBones.Count > 0; } }
        public Transform GetBoneTransform(HumanBodyBones bone)
        {
            Transform t;
            return StubBones.TryGetValue(bone, out t) ? t : null;
        }
    }

    public static class Application
    {
        public static string streamingAssetsPath = "";   // stub: settable
    }

    public static class Time
    {
        public static float deltaTime = 1f / 60f;        // stub: settable
    }

    public static class Debug
    {
        public static void Log(object message) { Console.WriteLine(message); }
        public static void LogWarning(object message) { Console.WriteLine("warning: " + message); }
        public static void LogError(object message) { Console.Error.WriteLine("error: " + message); }
    }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class TooltipAttribute : Attribute { public TooltipAttribute(string tooltip) { } }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class SerializeField : Attribute { }

    public class AsyncOperation : YieldInstruction { public bool isDone { get { return true; } } }
}

namespace UnityEngine.Networking
{
    public sealed class DownloadHandler { public byte[] data = new byte[0]; }
    public sealed class UnityWebRequestAsyncOperation : AsyncOperation { }

    // Stub: compile-only for the Android path; fails every request.
    public sealed class UnityWebRequest : IDisposable
    {
        public enum Result { InProgress, Success, ConnectionError, ProtocolError, DataProcessingError }
        public Result result = Result.ConnectionError;
        public string error = "stub UnityWebRequest";
        public DownloadHandler downloadHandler = new DownloadHandler();
        public static UnityWebRequest Get(string uri) { return new UnityWebRequest(); }
        public UnityWebRequestAsyncOperation SendWebRequest() { return new UnityWebRequestAsyncOperation(); }
        public void Dispose() { }
    }
}

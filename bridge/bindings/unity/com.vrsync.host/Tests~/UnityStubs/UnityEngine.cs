// Stubs of the parts of Unity's scripting API that the vrsync package uses, written from
// Unity's public scripting reference (docs.unity3d.com/ScriptReference): the signatures the
// package calls and only the behaviour its tests need. NOT Unity: this folder ends in `~`,
// so Unity never imports it, and it is compiled only by the package's Mono tests
// (bridge/bindings/unity/test.sh) into a UnityEngine.dll that never leaves the test's temp dir.
//
// The "GPU" of these stubs is CPU memory: a RenderTexture holds its pixels in a byte array
// in Unity's texture convention (row 0 is the BOTTOM row, as Texture2D.GetPixels,
// ReadPixels and AsyncGPUReadback give them); Camera.Render() calls a test-provided
// renderer (Camera.StubRenderer) that draws into the camera's target texture.

using System;
using System.Collections.Generic;
using System.Reflection;
using System.Runtime.InteropServices;
using Unity.Collections;
using Unity.Collections.LowLevel.Unsafe;

namespace UnityEngine
{
    public struct Vector2
    {
        public float x, y;
        public Vector2(float x, float y) { this.x = x; this.y = y; }
    }

    public struct Vector3
    {
        public float x, y, z;
        public Vector3(float x, float y, float z) { this.x = x; this.y = y; this.z = z; }
        public static Vector3 zero { get { return new Vector3(0, 0, 0); } }
        public static Vector3 operator +(Vector3 a, Vector3 b) { return new Vector3(a.x + b.x, a.y + b.y, a.z + b.z); }
        public static Vector3 operator *(Vector3 a, float d) { return new Vector3(a.x * d, a.y * d, a.z * d); }
        public override string ToString() { return string.Format("({0:F2}, {1:F2}, {2:F2})", x, y, z); }
    }

    public struct Quaternion
    {
        public float x, y, z, w;
        public Quaternion(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
        public static Quaternion identity { get { return new Quaternion(0, 0, 0, 1); } }

        /// <summary>Rotation by z, then x, then y degrees (Unity's order).</summary>
        public static Quaternion Euler(float x, float y, float z)
        {
            // Only yaw is needed by the tests.
            if (x != 0 || z != 0)
                throw new NotImplementedException("stub Quaternion.Euler: only yaw");
            double h = y * Math.PI / 360.0;
            return new Quaternion(0, (float)Math.Sin(h), 0, (float)Math.Cos(h));
        }
    }

    public static class Mathf
    {
        public const float Deg2Rad = (float)(Math.PI / 180.0);
        public const float Rad2Deg = (float)(180.0 / Math.PI);
        public static float Sin(float f) { return (float)Math.Sin(f); }
        public static float Cos(float f) { return (float)Math.Cos(f); }
        public static float Atan2(float y, float x) { return (float)Math.Atan2(y, x); }
        public static float Sqrt(float f) { return (float)Math.Sqrt(f); }
        public static float Min(float a, float b) { return Math.Min(a, b); }
        public static float Max(float a, float b) { return Math.Max(a, b); }
        public static float Clamp(float value, float min, float max) { return value < min ? min : value > max ? max : value; }
        public static float Repeat(float t, float length) { return Clamp(t - (float)Math.Floor(t / length) * length, 0, length); }
        public static float DeltaAngle(float current, float target)
        {
            float delta = Repeat(target - current, 360.0f);
            return delta > 180.0f ? delta - 360.0f : delta;
        }
    }

    public struct Rect
    {
        public float x, y, width, height;
        public Rect(float x, float y, float width, float height)
        {
            this.x = x; this.y = y; this.width = width; this.height = height;
        }
    }

    public static class Debug
    {
        /// <summary>Stub only: every message, for tests to check what was logged.</summary>
        public static readonly List<string> StubLog = new List<string>();

        static void Write(string level, object message)
        {
            string line = level + ": " + message;
            StubLog.Add(line);
            Console.Error.WriteLine(line);
        }

        public static void Log(object message) { Write("Log", message); }
        public static void LogWarning(object message) { Write("Warning", message); }
        public static void LogError(object message) { Write("Error", message); }
        public static void LogException(Exception exception) { Write("Exception", exception); }
    }

    public static class Time
    {
        /// <summary>Stub: the player loop advances these.</summary>
        public static float captureDeltaTime { get; set; }
        public static float deltaTime { get; internal set; }
        public static float time { get; internal set; }
        public static int frameCount { get; internal set; }
        public static float realtimeSinceStartup
        {
            get { return (float)StubClock.Elapsed.TotalSeconds; }
        }
        public static double realtimeSinceStartupAsDouble
        {
            get { return StubClock.Elapsed.TotalSeconds; }
        }

        static readonly System.Diagnostics.Stopwatch StubClock = System.Diagnostics.Stopwatch.StartNew();
    }

    public static class Application
    {
        /// <summary>Stub: settable so tests can point it at a temp dir.</summary>
        public static string streamingAssetsPath { get; set; }
        public static bool isPlaying { get; internal set; }
    }

    public static class SystemInfo
    {
        /// <summary>Stub: settable so tests can take the fallback path.</summary>
        public static bool supportsAsyncGPUReadback { get; set; }

        static SystemInfo() { supportsAsyncGPUReadback = true; }
    }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class SerializeField : Attribute { }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class TooltipAttribute : Attribute
    {
        public TooltipAttribute(string tooltip) { }
    }

    [AttributeUsage(AttributeTargets.Field, AllowMultiple = true)]
    public sealed class HeaderAttribute : Attribute
    {
        public HeaderAttribute(string header) { }
    }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class DisallowMultipleComponent : Attribute { }

    [AttributeUsage(AttributeTargets.Class, AllowMultiple = true)]
    public sealed class RequireComponent : Attribute
    {
        public RequireComponent(Type requiredComponent) { }
    }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class AddComponentMenu : Attribute
    {
        public AddComponentMenu(string menuName) { }
    }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class DefaultExecutionOrder : Attribute
    {
        public DefaultExecutionOrder(int order) { this.order = order; }
        public int order { get; private set; }
    }

    public class Object
    {
        public string name { get; set; }

        /// <summary>Destroys a GameObject's behaviours (OnDestroy) or a texture at once.</summary>
        public static void DestroyImmediate(Object obj)
        {
            var go = obj as GameObject;
            if (go == null)
            {
                Destroy(obj);
                return;
            }
            foreach (Transform child in new List<Transform>(go.transform.StubChildren))
                DestroyImmediate(child.gameObject);
            foreach (var c in go.StubComponents)
            {
                var b = c as Behaviour;
                if (b == null)
                    continue;
                var m = b.GetType().GetMethod("OnDestroy", BindingFlags.Instance | BindingFlags.Public | BindingFlags.NonPublic,
                    null, Type.EmptyTypes, null);
                if (m != null)
                    m.Invoke(b, null);
            }
        }

        public static void Destroy(Object obj)
        {
            var rt = obj as RenderTexture;
            if (rt != null)
                rt.Release();
            var tex = obj as Texture2D;
            if (tex != null)
                tex.StubFree();
        }

        // Unity's "destroyed objects compare equal to null" is not needed by the tests.
    }

    public class GameObject : Object
    {
        readonly List<Component> components = new List<Component>();

        public GameObject(string name)
        {
            this.name = name;
            transform = new Transform();
            transform.StubAttach(this);
            components.Add(transform);
        }

        public Transform transform { get; private set; }
        public bool activeInHierarchy { get { return true; } }

        public T AddComponent<T>() where T : Component, new()
        {
            var c = new T();
            c.StubAttach(this);
            components.Add(c);
            return c;
        }

        public T GetComponent<T>()
        {
            foreach (var c in components)
                if (c is T)
                    return (T)(object)c;
            return default(T);
        }

        internal IEnumerable<Component> StubComponents { get { return components; } }
    }

    public class Component : Object
    {
        public GameObject gameObject { get; private set; }
        public Transform transform { get { return gameObject.transform; } }

        internal void StubAttach(GameObject go)
        {
            gameObject = go;
            name = go.name;
        }

        public T GetComponent<T>() { return gameObject.GetComponent<T>(); }

        public T[] GetComponentsInChildren<T>(bool includeInactive)
        {
            var found = new List<T>();
            Collect(transform, found);
            return found.ToArray();
        }

        public T[] GetComponentsInChildren<T>() { return GetComponentsInChildren<T>(false); }

        static void Collect<T>(Transform t, List<T> found)
        {
            foreach (var c in t.gameObject.StubComponents)
                if (c is T)
                    found.Add((T)(object)c);
            foreach (var child in t.StubChildren)
                Collect(child, found);
        }
    }

    public class Transform : Component
    {
        readonly List<Transform> children = new List<Transform>();
        Transform parentTransform;

        public Vector3 position { get; set; }
        public Quaternion rotation { get; set; }

        public Transform() { rotation = Quaternion.identity; }

        public Transform parent
        {
            get { return parentTransform; }
            set
            {
                if (parentTransform != null)
                    parentTransform.children.Remove(this);
                parentTransform = value;
                if (value != null)
                    value.children.Add(this);
            }
        }

        public void SetParent(Transform p) { parent = p; }

        internal IEnumerable<Transform> StubChildren { get { return children; } }
    }

    public class Behaviour : Component
    {
        bool isEnabled = true;

        public bool enabled
        {
            get { return isEnabled; }
            set
            {
                if (isEnabled == value)
                    return;
                isEnabled = value;
                StubPlayer.Current?.EnabledChanged(this);
            }
        }

        public bool isActiveAndEnabled { get { return isEnabled; } }
    }

    public class MonoBehaviour : Behaviour
    {
    }

    public enum RenderTextureFormat
    {
        ARGB32 = 0,
        Depth = 1,
        ARGBHalf = 2,
        RGB565 = 4,
        ARGBFloat = 11,
        RFloat = 14,
        R8 = 16,
    }

    public enum TextureFormat
    {
        Alpha8 = 1,
        RGB24 = 3,
        RGBA32 = 4,
        ARGB32 = 5,
        R8 = 63,
        RFloat = 18,
    }

    public class Texture : Object
    {
        public virtual int width { get; set; }
        public virtual int height { get; set; }
    }

    public class RenderTexture : Texture
    {
        static RenderTexture activeTexture;

        /// <summary>Stub: the texture's "GPU memory", rows bottom-up, <see cref="StubBytesPerPixel"/>
        /// bytes per pixel (ARGB32: bytes R, G, B, A; R8: 1; RFloat: 4).</summary>
        public byte[] StubPixels;

        public RenderTexture(int width, int height, int depth, RenderTextureFormat format)
        {
            this.width = width;
            this.height = height;
            this.depth = depth;
            this.format = format;
        }

        public int depth { get; set; }
        public RenderTextureFormat format { get; set; }
        public bool IsCreated() { return StubPixels != null; }

        public bool Create()
        {
            if (StubPixels == null)
                StubPixels = new byte[width * height * StubBytesPerPixel];
            return true;
        }

        public void Release() { StubPixels = null; }

        public static RenderTexture active
        {
            get { return activeTexture; }
            set { activeTexture = value; }
        }

        public int StubBytesPerPixel { get { return BytesPerPixel(format); } }

        internal static int BytesPerPixel(RenderTextureFormat f)
        {
            switch (f)
            {
                case RenderTextureFormat.ARGB32: return 4;
                case RenderTextureFormat.R8: return 1;
                case RenderTextureFormat.RFloat: return 4;
                default: throw new NotImplementedException("stub RenderTexture format " + f);
            }
        }

        internal void RequireCreated()
        {
            if (StubPixels == null)
                throw new InvalidOperationException("stub: RenderTexture " + name + " was not created");
        }
    }

    public class Texture2D : Texture
    {
        IntPtr data;
        int length;

        public Texture2D(int width, int height, TextureFormat textureFormat, bool mipChain)
        {
            this.width = width;
            this.height = height;
            format = textureFormat;
            length = width * height * StubTexture.BytesPerPixel(textureFormat);
            data = Marshal.AllocHGlobal(length);
        }

        public TextureFormat format { get; private set; }

        /// <summary>Reads the active RenderTexture (rows bottom-up) into this texture's CPU data.</summary>
        public void ReadPixels(Rect source, int destX, int destY, bool recalculateMipMaps)
        {
            var rt = RenderTexture.active;
            if (rt == null)
                throw new InvalidOperationException("stub ReadPixels: no active RenderTexture");
            if (source.x != 0 || source.y != 0 || destX != 0 || destY != 0
                || (int)source.width != width || (int)source.height != height
                || rt.width != width || rt.height != height)
                throw new NotImplementedException("stub ReadPixels: only the whole texture");
            byte[] converted = StubTexture.Convert(rt, format);
            Marshal.Copy(converted, 0, data, converted.Length);
        }

        public void ReadPixels(Rect source, int destX, int destY)
        {
            ReadPixels(source, destX, destY, true);
        }

        public unsafe NativeArray<T> GetRawTextureData<T>() where T : struct
        {
            int size = Marshal.SizeOf(typeof(T));
            return NativeArrayUnsafeUtility.ConvertExistingDataToNativeArray<T>((void*)data, length / size, Allocator.None);
        }

        public void Apply() { }

        internal void StubFree()
        {
            if (data != IntPtr.Zero)
                Marshal.FreeHGlobal(data);
            data = IntPtr.Zero;
        }
    }

    /// <summary>Stub-only helpers for the texture formats (not Unity API).</summary>
    internal static class StubTexture
    {
        internal static int BytesPerPixel(TextureFormat f)
        {
            switch (f)
            {
                case TextureFormat.RGB24: return 3;
                case TextureFormat.RGBA32: return 4;
                case TextureFormat.R8: return 1;
                case TextureFormat.RFloat: return 4;
                default: throw new NotImplementedException("stub TextureFormat " + f);
            }
        }

        /// <summary>The render texture's pixels converted to <paramref name="to"/>, rows
        /// bottom-up as stored (what the GPU's format conversion does).</summary>
        internal static byte[] Convert(RenderTexture rt, TextureFormat to)
        {
            rt.RequireCreated();
            int n = rt.width * rt.height;
            int inBpp = rt.StubBytesPerPixel;
            int outBpp = BytesPerPixel(to);
            var output = new byte[n * outBpp];
            bool same = (rt.format == RenderTextureFormat.ARGB32 && to == TextureFormat.RGBA32)
                || (rt.format == RenderTextureFormat.R8 && to == TextureFormat.R8)
                || (rt.format == RenderTextureFormat.RFloat && to == TextureFormat.RFloat);
            if (same)
                return (byte[])rt.StubPixels.Clone();
            if (rt.format == RenderTextureFormat.ARGB32 && to == TextureFormat.RGB24)
            {
                for (int i = 0; i < n; i++)
                    Buffer.BlockCopy(rt.StubPixels, i * inBpp, output, i * outBpp, 3);
                return output;
            }
            throw new NotImplementedException(string.Format("stub conversion {0} -> {1}", rt.format, to));
        }
    }

    public struct Color
    {
        public float r, g, b, a;
        public Color(float r, float g, float b, float a) { this.r = r; this.g = g; this.b = b; this.a = a; }
        public Color(float r, float g, float b) : this(r, g, b, 1) { }
        public static Color black { get { return new Color(0, 0, 0, 1); } }
        public static Color red { get { return new Color(1, 0, 0, 1); } }
    }

    public enum CameraClearFlags
    {
        Skybox = 1,
        SolidColor = 2,
        Depth = 3,
        Nothing = 4,
    }

    public class Camera : Behaviour
    {
        public Camera() { rect = new Rect(0, 0, 1, 1); clearFlags = CameraClearFlags.Skybox; }

        public CameraClearFlags clearFlags { get; set; }
        public Color backgroundColor { get; set; }
        /// <summary>The viewport, normalized; (0, 0) is the bottom left.</summary>
        public Rect rect { get; set; }

        /// <summary>Stub only: what Camera.Render() draws (the tests' "scene").</summary>
        public static Action<Camera> StubRenderer;

        /// <summary>Stub only: how many times Render() ran.</summary>
        public int StubRenders;

        public RenderTexture targetTexture { get; set; }
        public float fieldOfView { get; set; }
        public float aspect { get; set; }

        public void Render()
        {
            if (targetTexture == null)
                throw new InvalidOperationException("stub Camera.Render: no targetTexture");
            targetTexture.RequireCreated();
            StubRenders++;
            if (StubRenderer != null)
            {
                StubRenderer(this);
                return;
            }
            // No scene in the stubs: a solid-colour clear of the viewport is all that renders.
            if (clearFlags != CameraClearFlags.SolidColor)
                return;
            RenderTexture rt = targetTexture;
            if (rt.format != RenderTextureFormat.ARGB32)
                throw new NotImplementedException("stub Camera.Render: clears ARGB32 targets only");
            var c = new[] { backgroundColor.r, backgroundColor.g, backgroundColor.b, backgroundColor.a };
            int x0 = (int)Math.Round(rect.x * rt.width), x1 = (int)Math.Round((rect.x + rect.width) * rt.width);
            int y0 = (int)Math.Round(rect.y * rt.height), y1 = (int)Math.Round((rect.y + rect.height) * rt.height);
            for (int y = y0; y < y1; y++)  // rows counted from the bottom, as the viewport
                for (int x = x0; x < x1; x++)
                    for (int k = 0; k < 4; k++)
                        rt.StubPixels[(y * rt.width + x) * 4 + k] = (byte)Math.Round(Math.Min(1, Math.Max(0, c[k])) * 255);
        }
    }

    public static class Graphics
    {
        /// <summary>Copies <paramref name="source"/> into <paramref name="dest"/> through
        /// texture coordinates <c>uv * scale + offset</c> (point sampling; same size and
        /// format only in this stub). scale (1, -1), offset (0, 1) flips vertically.</summary>
        public static void Blit(Texture source, RenderTexture dest, Vector2 scale, Vector2 offset)
        {
            var src = source as RenderTexture;
            if (src == null || src.width != dest.width || src.height != dest.height || src.format != dest.format)
                throw new NotImplementedException("stub Blit: RenderTextures of one size and format only");
            src.RequireCreated();
            dest.RequireCreated();
            int w = dest.width, h = dest.height, bpp = dest.StubBytesPerPixel;
            for (int y = 0; y < h; y++)
            {
                double v = (y + 0.5) / h * scale.y + offset.y;
                int sy = Math.Min(h - 1, Math.Max(0, (int)Math.Floor(v * h)));
                for (int x = 0; x < w; x++)
                {
                    double u = (x + 0.5) / w * scale.x + offset.x;
                    int sx = Math.Min(w - 1, Math.Max(0, (int)Math.Floor(u * w)));
                    Buffer.BlockCopy(src.StubPixels, (sy * w + sx) * bpp, dest.StubPixels, (y * w + x) * bpp, bpp);
                }
            }
        }

        public static void Blit(Texture source, RenderTexture dest)
        {
            Blit(source, dest, new Vector2(1, 1), new Vector2(0, 0));
        }
    }

    /// <summary>
    /// Stub only (not Unity API): a player loop for tests. Calls the message methods Unity
    /// calls by name (Awake, OnEnable, Start, Update, LateUpdate, OnDisable, OnDestroy) on
    /// the behaviours of its objects, ordered by [DefaultExecutionOrder]; each frame
    /// advances Time by Time.captureDeltaTime when it is set (as Unity does), else by real
    /// time; at the end of a frame the "GPU" finishes the pending async readbacks.
    /// </summary>
    public sealed class StubPlayer
    {
        internal static StubPlayer Current;
        readonly List<GameObject> objects = new List<GameObject>();
        readonly HashSet<Behaviour> started = new HashSet<Behaviour>();
        double lastRealtime;

        public StubPlayer() { Current = this; }

        public void Add(GameObject go) { objects.Add(go); }

        List<Behaviour> Behaviours()
        {
            var all = new List<Behaviour>();
            foreach (var go in objects)
                Gather(go.transform, all);
            all.Sort((a, b) => Order(a).CompareTo(Order(b)));
            return all;
        }

        static void Gather(Transform t, List<Behaviour> all)
        {
            foreach (var c in t.gameObject.StubComponents)
                if (c is MonoBehaviour)
                    all.Add((Behaviour)c);
            foreach (var child in t.StubChildren)
                Gather(child, all);
        }

        static int Order(Behaviour b)
        {
            var a = (DefaultExecutionOrder)Attribute.GetCustomAttribute(b.GetType(), typeof(DefaultExecutionOrder));
            return a == null ? 0 : a.order;
        }

        static void Send(Behaviour b, string message)
        {
            MethodInfo m = b.GetType().GetMethod(message,
                BindingFlags.Instance | BindingFlags.Public | BindingFlags.NonPublic, null, Type.EmptyTypes, null);
            if (m != null)
                m.Invoke(b, null);
        }

        /// <summary>Enters play mode: Awake and OnEnable of every behaviour.</summary>
        public void Play()
        {
            Application.isPlaying = true;
            lastRealtime = Time.realtimeSinceStartupAsDouble;
            var all = Behaviours();
            foreach (var b in all)
                Send(b, "Awake");
            foreach (var b in all)
                if (b.enabled)
                    Send(b, "OnEnable");
        }

        internal void EnabledChanged(Behaviour b)
        {
            if (!Application.isPlaying)
                return;
            Send(b, b.enabled ? "OnEnable" : "OnDisable");
        }

        /// <summary>One frame: Start (first time), Update, LateUpdate, then the GPU work.</summary>
        public void Frame()
        {
            double now = Time.realtimeSinceStartupAsDouble;
            float dt = Time.captureDeltaTime > 0 ? Time.captureDeltaTime : (float)(now - lastRealtime);
            lastRealtime = now;
            Time.deltaTime = dt;
            Time.time += dt;
            Time.frameCount++;
            var all = Behaviours();
            foreach (var b in all)
                if (b.enabled && started.Add(b))
                    Send(b, "Start");
            foreach (var b in all)
                if (b.enabled)
                    Send(b, "Update");
            foreach (var b in all)
                if (b.enabled)
                    Send(b, "LateUpdate");
            Rendering.AsyncGPUReadback.StubCompleteAll();
        }

        /// <summary>Leaves play mode: OnDisable and OnDestroy of every behaviour.</summary>
        public void Stop()
        {
            var all = Behaviours();
            foreach (var b in all)
                if (b.enabled)
                    Send(b, "OnDisable");
            foreach (var b in all)
                Send(b, "OnDestroy");
            Application.isPlaying = false;
            Current = null;
        }
    }
}

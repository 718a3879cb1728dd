// Stand-ins for the UnityEngine types the exported behaviour, asset and importer use (names and
// signatures as in Unity's scripting API), so that tests can compile them without Unity installed.
namespace UnityEngine
{
    public class Object
    {
        public string name = "";
        public static void Destroy(Object o) { }
    }
    public class ScriptableObject : Object
    {
        public static T CreateInstance<T>() where T : ScriptableObject, new() { return new T(); }
    }
    public class Component : Object
    {
        public Transform transform = null;
        public T GetComponent<T>() where T : Component { return null; }
    }
    public class Behaviour : Component { public bool enabled = true; }
    public class MonoBehaviour : Behaviour { }
    public struct Vector3 { public float x, y, z; }
    public struct Vector4
    {
        public float x, y, z, w;
        public Vector4(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
        public static implicit operator Vector4(Vector3 v) { return new Vector4(v.x, v.y, v.z, 0f); }
    }
    public struct Quaternion { public Vector3 eulerAngles { get { return new Vector3(); } } }
    public class Transform : Component
    {
        public Quaternion rotation = new Quaternion();
        public Vector3 position = new Vector3();
        public Vector3 right { get { return new Vector3(); } }
        public Vector3 up { get { return new Vector3(); } }
        public Vector3 forward { get { return new Vector3(); } }
    }
    public class Camera : Behaviour
    {
        public static Camera main = null;
        public float fieldOfView = 60f;
        public float aspect = 1f;
        public int pixelHeight = 1440;
    }
    public class Renderer : Component { public Material material = null; }
    public class TextAsset : Object { public byte[] bytes { get { return new byte[0]; } } }
    public class Texture : Object { }
    public enum TextureFormat { R8 = 63 }
    public enum TextureWrapMode { Repeat, Clamp }
    public enum FilterMode { Point, Bilinear, Trilinear }
    public class Texture2D : Texture
    {
        public Texture2D(int width, int height, TextureFormat format, bool mipChain, bool linear) { }
        public TextureWrapMode wrapModeU, wrapModeV;
        public FilterMode filterMode;
        public void LoadRawTextureData(byte[] data) { }
        public void Apply(bool updateMipmaps, bool makeNoLongerReadable) { }
    }
    public class Material : Object
    {
        public void SetFloat(string name, float value) { }
        public void SetVector(string name, Vector4 value) { }
        public Vector4 GetVector(string name) { return new Vector4(); }
        public void SetTexture(string name, Texture value) { }
    }
    public static class Application { public static string streamingAssetsPath { get { return ""; } } }
    public static class SystemInfo { public static int maxTextureSize { get { return 16384; } } }
    public static class Time
    {
        public static float time { get { return TestTime; } }
        public static float TestTime = 0f; // set by test harnesses
        public static float deltaTime { get { return 0f; } }
    }
    public static class Debug
    {   // counted, so that a test harness can check what the behaviour logs
        public static int Errors, Warnings;
        public static void LogError(object message) { Errors++; System.Console.Error.WriteLine("error: " + message); }
        public static void LogWarning(object message) { Warnings++; System.Console.Error.WriteLine("warning: " + message); }
    }
    public class TooltipAttribute : System.Attribute { public TooltipAttribute(string tooltip) { } }
    public class HideInInspectorAttribute : System.Attribute { }
}

namespace UnityEngine.Video
{
    public class VideoPlayer : UnityEngine.Behaviour
    {
        public delegate void EventHandler(VideoPlayer source);
        public double time = 0;
        public long frame = -1;
        public float frameRate = 0f;
        public bool isPrepared = false;
        public bool isPlaying = false;
        public event EventHandler seekCompleted;
        public event EventHandler loopPointReached;
        public void RaiseForTests() { if (seekCompleted != null) seekCompleted(this); if (loopPointReached != null) loopPointReached(this); }
    }
}

// The editor API the importer uses (UnityEditor.AssetImporters, 2020.2+).
namespace UnityEditor.AssetImporters
{
    public class AssetImportContext
    {
        public string assetPath = "";
        public void LogImportError(string msg) { }
        public void AddObjectToAsset(string identifier, UnityEngine.Object obj) { }
        public void SetMainObject(UnityEngine.Object obj) { }
    }
    public abstract class ScriptedImporter : UnityEngine.Object
    {
        public abstract void OnImportAsset(AssetImportContext ctx);
    }
    public class ScriptedImporterAttribute : System.Attribute
    {
        public ScriptedImporterAttribute(int version, string ext) { }
        public ScriptedImporterAttribute(int version, string[] exts, string[] overrideExts) { }
    }
}

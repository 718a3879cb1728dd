// Stand-ins for the UnityEngine types VimsimEpofBehaviour.cs uses (names and signatures as in
// Unity's scripting API), so that tests can compile the behaviour without Unity installed.
namespace UnityEngine
{
    public class Object { public string name = ""; }
    public class Component : Object { public Transform transform = null; }
    public class Behaviour : Component { public bool enabled = true; }
    public class MonoBehaviour : Behaviour { }
    public struct Vector3 { public float x, y, z; }
    public struct Quaternion { public Vector3 eulerAngles { get { return new Vector3(); } } }
    public class Transform : Component { public Quaternion rotation = new Quaternion(); }
    public class Camera : Behaviour { public static Camera main = null; }
    public class TextAsset : Object { public byte[] bytes { get { return new byte[0]; } } }
    public class Material : Object { public void SetFloat(string name, float value) { } }
    public static class Application { public static string streamingAssetsPath { get { return ""; } } }
    public static class Time
    {
        public static float time { get { return 0f; } }
        public static float deltaTime { get { return 0f; } }
    }
    public static class Debug { public static void LogError(object message) { } }
    public class TooltipAttribute : System.Attribute { public TooltipAttribute(string tooltip) { } }
}

namespace UnityEngine.Video
{
    public class VideoPlayer : UnityEngine.Behaviour { public double time = 0; }
}

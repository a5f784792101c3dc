// The few UnityEngine types and members the package's Unity glue (Runtime/Unity) and samples use,
// with Unity's signatures and no behaviour: tests/unity.rs compiles them against it with Mono to
// check their C# without Unity. Add a member here (with Unity's exact signature) when the glue or
// a sample starts using it.
#pragma warning disable 1591, 0649, 0067
using System;

namespace UnityEngine
{
    public class Object
    {
        public string name { get; set; }
        public static T Instantiate<T>(T original, Vector3 position, Quaternion rotation, Transform parent) where T : Object { return original; }
    }

    public class Component : Object
    {
        public Transform transform { get { return null; } }
        public GameObject gameObject { get { return null; } }
        public T[] GetComponentsInChildren<T>(bool includeInactive) { return new T[0]; }
    }

    public class Behaviour : Component
    {
        public bool enabled { get; set; }
    }

    public class MonoBehaviour : Behaviour { }

    public class ScriptableObject : Object { }

    public sealed class GameObject : Object
    {
        public Transform transform { get { return null; } }
    }

    public class Transform : Component
    {
        public Vector3 position { get; set; }
        public Quaternion rotation { get; set; }
        public Quaternion localRotation { get; set; }
        public Vector3 eulerAngles { get; set; }
        public void SetPositionAndRotation(Vector3 position, Quaternion rotation) { }
    }

    public sealed class AnimationClip : Object
    {
        public float frameRate { get; set; }
        public void SampleAnimation(GameObject go, float time) { }
    }

    public struct Vector3
    {
        public float x, y, z;
        public Vector3(float x, float y, float z) { this.x = x; this.y = y; this.z = z; }
        public static Vector3 operator +(Vector3 a, Vector3 b) { return new Vector3(a.x + b.x, a.y + b.y, a.z + b.z); }
    }

    public struct Quaternion
    {
        public float x, y, z, w;
        public Quaternion(float x, float y, float z, float w) { this.x = x; this.y = y; this.z = z; this.w = w; }
        public static Quaternion identity { get { return new Quaternion(0f, 0f, 0f, 1f); } }
    }

    public static class Mathf
    {
        public const float Deg2Rad = 0.0174532924f;
        public static int CeilToInt(float f) { return (int)Math.Ceiling(f); }
        public static float Sqrt(float f) { return (float)Math.Sqrt(f); }
        public static int Min(int a, int b) { return Math.Min(a, b); }
        public static int Max(int a, int b) { return Math.Max(a, b); }
    }

    public static class Time
    {
        public static float deltaTime { get { return 0f; } }
    }

    public static class Application
    {
        public static string streamingAssetsPath { get { return ""; } }
    }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class SerializeField : Attribute { }

    [AttributeUsage(AttributeTargets.Field)]
    public sealed class TooltipAttribute : Attribute
    {
        public TooltipAttribute(string tooltip) { }
    }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class DisallowMultipleComponent : Attribute { }

    [AttributeUsage(AttributeTargets.Class)]
    public sealed class CreateAssetMenuAttribute : Attribute
    {
        public string menuName { get; set; }
        public string fileName { get; set; }
    }
}

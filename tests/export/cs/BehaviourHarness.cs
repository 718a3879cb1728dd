// Drives VimsimEpofBehaviour (compiled against UnityEngineStub.cs) like Unity would: Awake, then
// Update once per rendered frame, with a stub VideoPlayer whose frame, rate and state the script
// sets. Usage: BehaviourHarness EXPORT_DIR SCRIPT OUT
//   SCRIPT: int32 n, n x (int64 frame, float32 frameRate, int32 flags: 1 playing, 2 prepared,
//           4 raise seekCompleted and loopPointReached before this Update)
//   OUT:    n x (float32 epof, raw, eased, drawn); then prints "warnings W errors E"
using System;
using System.IO;
using System.Reflection;
using System.Threading;
using UnityEngine;
using UnityEngine.Video;
using Vimsim;

static class BehaviourHarness
{
    static void Call(object o, string name)
    {
        o.GetType().GetMethod(name, BindingFlags.NonPublic | BindingFlags.Instance).Invoke(o, null);
    }

    static int Main(string[] a)
    {
        var b = new VimsimEpofBehaviour();
        b.streamingAssetsFolder = Path.GetFullPath(a[0]);
        b.head = new Transform();
        var video = new VideoPlayer();
        b.video = video;
        Call(b, "Awake");
        Call(b, "Start");
        for (int i = 0; i < 600 && b.Runtime == null; i++) { Call(b, "Update"); Thread.Sleep(10); }
        if (b.Runtime == null) { Console.WriteLine("not loaded"); return 3; }
        using (var br = new BinaryReader(File.OpenRead(a[1])))
        using (var bw = new BinaryWriter(File.Create(a[2])))
        {
            int n = br.ReadInt32();
            for (int i = 0; i < n; i++)
            {
                video.frame = br.ReadInt64();
                video.frameRate = br.ReadSingle();
                int flags = br.ReadInt32();
                video.isPlaying = (flags & 1) != 0;
                video.isPrepared = (flags & 2) != 0;
                if ((flags & 4) != 0) video.RaiseForTests();
                Call(b, "Update");
                bw.Write(b.Epof); bw.Write(b.RawOpacity); bw.Write(b.EasedOpacity); bw.Write(b.DrawnOpacity);
            }
        }
        Console.WriteLine("warnings " + UnityEngine.Debug.Warnings + " errors " + UnityEngine.Debug.Errors);
        return 0;
    }
}

// Test and bench harness for the exported C# runtime (compiled with VimsimEpof.cs by mcs).
// Several commands separated by ";" run in one process.
//   query BIN QUERIES OUT [BIN QUERIES OUT ...]
//                            QUERIES: int32 n, n x (float64 t, float32 yaw, pitch, roll);
//                            OUT: n x (float32 epof, float32 opacity, int32 frame)
//   ease BIN IN OUT          IN: int32 n, n float32 opacities (one per video frame); OUT: n float32
//   play BIN QUERIES OUT     the QUERIES in order, one per video frame: OUT n x float32 (Step of
//                            Opacity(Epof), Update of the same with dt = 1 / fps) from CreateEasing
//   table BIN OUT            OUT: the paper-mode overlap table, float32
//   unity IN OUT             IN: int32 n, n x float32 (x, y, z, offset); OUT: n x float32 (yaw, pitch, roll)
//   load BIN                 prints "ok MODE" or "VimsimLoadException|FILE|PROBLEM" (exit 3)
//   clock BIN QUERIES OUT    a VimsimPlaybackClock fed the QUERIES in order, t = the player's video
//                            frame: OUT n x (float32 epof, raw, eased, int32 flags: 1 in range, 2 restarted)
//   covers BIN QUERIES OUT   OUT n x (int32 Covers(t), float32 Epof(t, pose))
//   grains BIN OUT           OUT: the grain layout, n x 3 float32
//   mask BIN WIDTH OUT       OUT: VimsimGrainMask.Build, width x width / 2 bytes, row 0 north
//   bench BIN N SEED [QUERIES]  prints per-call microseconds, wall and CPU: random poses, the
//                            same again, 500 of them with their weights cached, the QUERIES in
//                            order from a fresh cache
using System;
using System.Diagnostics;
using System.IO;
using Vimsim;

static class EpofHarness
{
    static int Main(string[] args)
    {   // commands separated by ";" run in one process (the paper-mode table is built once)
        var cmd = new System.Collections.Generic.List<string>();
        int rc = 0;
        foreach (string x in args)
        {
            if (x == ";") { rc = Run(cmd.ToArray()); cmd.Clear(); if (rc != 0) return rc; }
            else cmd.Add(x);
        }
        return cmd.Count > 0 ? Run(cmd.ToArray()) : rc;
    }

    static int Run(string[] a)
    {
        switch (a[0])
        {
            case "query":
                for (int i = 1; i + 2 < a.Length; i += 3) Query(a[i], a[i + 1], a[i + 2]);
                return 0;
            case "ease": return Ease(a[1], a[2], a[3]);
            case "play": return Play(a[1], a[2], a[3]);
            case "table": return Table(a[1], a[2]);
            case "unity": return Unity(a[1], a[2]);
            case "load": return LoadOnly(a[1]);
            case "clock": return Clock(a[1], a[2], a[3]);
            case "covers": return Covers(a[1], a[2], a[3]);
            case "grains": return Grains(a[1], a[2]);
            case "mask": File.WriteAllBytes(a[3], VimsimGrainMask.Build(VimsimEpof.Load(a[1]), int.Parse(a[2]))); return 0;
            case "bench": return Bench(a[1], int.Parse(a[2]), int.Parse(a[3]), a.Length > 4 ? a[4] : null);
        }
        Console.Error.WriteLine("unknown command " + a[0]);
        return 2;
    }

    static VimsimEpof Timed(string bin)
    {
        var sw = Stopwatch.StartNew();
        var e = VimsimEpof.Load(bin);
        Console.WriteLine("load_ms " + sw.Elapsed.TotalMilliseconds.ToString("R"));
        return e;
    }

    static void ReadQueries(string path, out double[] t, out float[] y, out float[] p, out float[] r)
    {
        using (var br = new BinaryReader(File.OpenRead(path)))
        {
            int n = br.ReadInt32();
            t = new double[n]; y = new float[n]; p = new float[n]; r = new float[n];
            for (int i = 0; i < n; i++) { t[i] = br.ReadDouble(); y[i] = br.ReadSingle(); p[i] = br.ReadSingle(); r[i] = br.ReadSingle(); }
        }
    }

    static int Query(string bin, string qpath, string outPath)
    {
        var e = Timed(bin);
        double[] t; float[] y, p, r;
        ReadQueries(qpath, out t, out y, out p, out r);
        using (var bw = new BinaryWriter(File.Create(outPath)))
            for (int i = 0; i < t.Length; i++)
            {
                float v = e.Epof(t[i], y[i], p[i], r[i]);
                bw.Write(v); bw.Write(e.RawOpacity(v)); bw.Write(e.FrameAt(t[i]));
            }
        Console.WriteLine("mode " + e.Mode);
        return 0;
    }

    static int Ease(string bin, string inPath, string outPath)
    {
        var e = VimsimEpof.Load(bin);
        var ez = e.CreateEasing();
        using (var br = new BinaryReader(File.OpenRead(inPath)))
        using (var bw = new BinaryWriter(File.Create(outPath)))
        {
            int n = br.ReadInt32();
            for (int i = 0; i < n; i++) bw.Write(ez.Step(br.ReadSingle()));
        }
        return 0;
    }

    static int Play(string bin, string qpath, string outPath)
    {
        var e = VimsimEpof.Load(bin);
        OpacityEasing step = e.CreateEasing(), upd = e.CreateEasing();
        double[] t; float[] y, p, r;
        ReadQueries(qpath, out t, out y, out p, out r);
        using (var bw = new BinaryWriter(File.Create(outPath)))
            for (int i = 0; i < t.Length; i++)
            {
                float o = e.RawOpacity(e.Epof(t[i], y[i], p[i], r[i]));
                bw.Write(step.Step(o));
                bw.Write(upd.Update(o, 1.0 / e.Fps));
            }
        return 0;
    }

    static int Clock(string bin, string qpath, string outPath)
    {
        var e = VimsimEpof.Load(bin);
        var clock = e.CreatePlaybackClock();
        double[] t; float[] y, p, r;
        ReadQueries(qpath, out t, out y, out p, out r);
        using (var bw = new BinaryWriter(File.Create(outPath)))
            for (int i = 0; i < t.Length; i++)
            {
                int restarts = clock.Restarts;
                bool ok = clock.Advance((long)t[i], y[i], p[i], r[i]);
                bw.Write(clock.Epof); bw.Write(clock.RawOpacity); bw.Write(clock.EasedOpacity);
                bw.Write((ok ? 1 : 0) | (clock.Restarts != restarts ? 2 : 0));
            }
        return 0;
    }

    static int Covers(string bin, string qpath, string outPath)
    {
        var e = VimsimEpof.Load(bin);
        double[] t; float[] y, p, r;
        ReadQueries(qpath, out t, out y, out p, out r);
        using (var bw = new BinaryWriter(File.Create(outPath)))
            for (int i = 0; i < t.Length; i++) { bw.Write(e.Covers(t[i]) ? 1 : 0); bw.Write(e.Epof(t[i], y[i], p[i], r[i])); }
        return 0;
    }

    static int Grains(string bin, string outPath)
    {
        var e = VimsimEpof.Load(bin);
        using (var bw = new BinaryWriter(File.Create(outPath)))
            foreach (float v in e.GrainCenters) bw.Write(v);
        return 0;
    }

    static int Table(string bin, string outPath)
    {
        var e = Timed(bin);
        using (var bw = new BinaryWriter(File.Create(outPath)))
            foreach (float v in e.OverlapTable) bw.Write(v);
        return 0;
    }

    static int Unity(string inPath, string outPath)
    {
        using (var br = new BinaryReader(File.OpenRead(inPath)))
        using (var bw = new BinaryWriter(File.Create(outPath)))
        {
            int n = br.ReadInt32();
            for (int i = 0; i < n; i++)
            {
                float x = br.ReadSingle(), y = br.ReadSingle(), z = br.ReadSingle(), o = br.ReadSingle();
                float yaw, pitch, roll;
                VimsimEpof.FromUnityEuler(x, y, z, o, out yaw, out pitch, out roll);
                bw.Write(yaw); bw.Write(pitch); bw.Write(roll);
            }
        }
        return 0;
    }

    static int LoadOnly(string bin)
    {
        try
        {
            var e = VimsimEpof.Load(bin);
            Console.WriteLine("ok " + e.Mode + " " + e.OpacityRule + " " + e.OpacityScale);
            return 0;
        }
        catch (VimsimLoadException ex)
        {
            Console.WriteLine("VimsimLoadException|" + ex.FilePath + "|" + ex.Problem + "|" + ex.Field);
            return 3;
        }
    }

    static void Report(string name, Stopwatch sw, TimeSpan cpu0, int n)
    {
        double cpu = (Process.GetCurrentProcess().TotalProcessorTime - cpu0).TotalMilliseconds;
        Console.WriteLine(name + "_us " + (sw.Elapsed.TotalMilliseconds * 1000.0 / n).ToString("R"));
        Console.WriteLine(name + "_cpu_us " + (cpu * 1000.0 / n).ToString("R"));
    }

    static int Bench(string bin, int n, int seed, string qpath)
    {
        var e = Timed(bin);
        var rng = new Random(seed);
        var t = new double[n]; var y = new float[n]; var p = new float[n]; var r = new float[n];
        double dur = e.FrameCount / e.Fps;
        for (int i = 0; i < n; i++)
        {
            t[i] = rng.NextDouble() * dur + e.StartFrame / e.Fps;
            y[i] = (float)(rng.NextDouble() * 360 - 180);
            p[i] = (float)(Math.Asin(rng.NextDouble() * 2 - 1) * 180 / Math.PI);
            r[i] = (float)(rng.NextDouble() * 60 - 30);
        }
        float sink = 0;
        for (int i = 0; i < Math.Min(n, 2000); i++) sink += e.Epof(t[i], y[i], p[i], r[i]); // JIT warm-up
        int warmBins = e.CachedBins;
        // Wall time and this process's CPU time (the machine may be shared: CPU time is the cost).
        var proc = Process.GetCurrentProcess();
        var sw = Stopwatch.StartNew();
        var cpu0 = proc.TotalProcessorTime;
        for (int i = 0; i < n; i++) sink += e.Epof(t[i], y[i], p[i], r[i]);
        Report("random", sw, cpu0, n);
        // The same poses again: in sphere mode every weight bin is now cached (up to the cache size).
        sw.Restart(); cpu0 = Process.GetCurrentProcess().TotalProcessorTime;
        for (int i = 0; i < n; i++) sink += e.Epof(t[i], y[i], p[i], r[i]);
        Report("repeat", sw, cpu0, n);
        Console.WriteLine("bins " + e.CachedBins + " warm_bins " + warmBins);
        // Cached: 500 poses whose weight bins are all in the cache (a still or slow head).
        int m = Math.Min(n, 500);
        for (int i = 0; i < m; i++) sink += e.Epof(t[i], y[i], p[i], r[i]);
        int passes = Math.Max(1, n / m);
        sw.Restart(); cpu0 = Process.GetCurrentProcess().TotalProcessorTime;
        for (int k = 0; k < passes; k++)
            for (int i = 0; i < m; i++) sink += e.Epof(t[i], y[i], p[i], r[i]);
        Report("cached", sw, cpu0, passes * m);
        if (qpath != null)
        {
            double[] qt; float[] qy, qp, qr;
            ReadQueries(qpath, out qt, out qy, out qp, out qr);
            var e2 = VimsimEpof.Load(bin); // fresh cache
            for (int i = 0; i < Math.Min(qt.Length, 200); i++) sink += e2.Epof(qt[i], qy[i], qp[i], qr[i]);
            // The trace in order, repeated from a fresh cache each time (enough calls to time).
            int reps = Math.Max(1, n / qt.Length), bins = 0;
            double wall = 0, cpu = 0;
            for (int rep = 0; rep < reps; rep++)
            {
                e2 = VimsimEpof.Load(bin);
                sw.Restart(); cpu0 = Process.GetCurrentProcess().TotalProcessorTime;
                for (int i = 0; i < qt.Length; i++) sink += e2.Epof(qt[i], qy[i], qp[i], qr[i]);
                wall += sw.Elapsed.TotalMilliseconds;
                cpu += (Process.GetCurrentProcess().TotalProcessorTime - cpu0).TotalMilliseconds;
                bins = e2.CachedBins;
            }
            Console.WriteLine("path_us " + (wall * 1000.0 / (reps * qt.Length)).ToString("R"));
            Console.WriteLine("path_cpu_us " + (cpu * 1000.0 / (reps * qt.Length)).ToString("R"));
            Console.WriteLine("path_bins " + bins + " of " + qt.Length);
        }
        Console.WriteLine("sink " + sink);
        return 0;
    }
}

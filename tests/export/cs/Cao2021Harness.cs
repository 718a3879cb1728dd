// Test harness of VimsimCao2021.cs: args DIR QUERIES OUT; QUERIES holds "frame yaw pitch" lines,
// OUT gets "flow opacity" lines (round-trip doubles).
using System;
using System.Globalization;
using System.IO;
using System.Text;

public static class Cao2021Harness
{
    public static int Main(string[] args)
    {
        var rt = Vimsim.VimsimCao2021.LoadFolder(args[0]);
        var sb = new StringBuilder();
        var inv = CultureInfo.InvariantCulture;
        foreach (var line in File.ReadAllLines(args[1]))
        {
            if (line.Trim().Length == 0) continue;
            var f = line.Split(' ');
            int k = int.Parse(f[0], inv);
            double y = double.Parse(f[1], inv), p = double.Parse(f[2], inv);
            sb.Append(rt.Flow(k, y, p).ToString("R", inv)).Append(' ')
              .Append(rt.Opacity(k, y, p).ToString("R", inv)).Append('\n');
        }
        File.WriteAllText(args[2], sb.ToString());
        return 0;
    }
}

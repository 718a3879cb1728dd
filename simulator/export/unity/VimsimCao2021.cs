// The authors' Unity runtime rule (vimsim --preset cao2021-code), written from its description
// in vimsim's docs/parity.md: no UnityEngine dependency; vimsim's Python
// (simulator/mitigation/cao2021.py) gives the same numbers (tests: 1e-7).
//
// A folder in the authors' layout (vimsim export --format cao-csv): one CSV per window,
// horizontal_<yaw>_vertical_<pitch>.csv (centres in degrees), a header line ",0" then
// "frame,value" rows in window px/frame, and percentileData.csv (low and high px/frame).
//
// At video frame k (0-based) with head yaw / pitch in degrees (yaw + right, pitch + up):
// - each angle wrapped to (-180, 180]; yaw candidates ceil(yaw/s)*s and floor(yaw/s)*s, each
//   above 180-s moved by -360, or below -(180-s) by +360; pitch candidates ceil/floor of
//   pitch/sp times sp; in each axis the smaller plain absolute difference wins (a tie: the
//   ceil candidate); pitch clamped to the folder's rows;
// - the window's list is the number after the comma of every non-empty line, the header
//   ",0" included: [0, row 0, row 1, ...]; the flow is list[k-1] (row k-2), 0 for k < 1 and
//   beyond the list;
// - opacity = clamp((flow - low) / (high - low), 0, 1).
using System;
using System.Collections.Generic;
using System.Globalization;
using System.IO;

namespace Vimsim
{
    public sealed class VimsimCao2021
    {
        public const double DefaultLowPx = 0.18;
        public const double DefaultHighPx = 53.73;

        readonly Dictionary<string, float[]> lists;
        public readonly double YawStepDeg, PitchStepDeg, PitchMinDeg, PitchMaxDeg, LowPx, HighPx;

        public VimsimCao2021(Dictionary<string, float[]> lists, double yawStepDeg, double pitchStepDeg,
                             double pitchMinDeg, double pitchMaxDeg, double lowPx, double highPx)
        {
            if (!(highPx > lowPx)) throw new ArgumentException("percentileData: low must be below high");
            this.lists = lists;
            YawStepDeg = yawStepDeg; PitchStepDeg = pitchStepDeg;
            PitchMinDeg = pitchMinDeg; PitchMaxDeg = pitchMaxDeg;
            LowPx = lowPx; HighPx = highPx;
        }

        /// <summary>Their reader: the number after the comma of every non-empty line.</summary>
        public static float[] ReadList(string text)
        {
            var values = new List<float>();
            foreach (var raw in text.Split('\n'))
            {
                var line = raw.Trim();
                if (line.Length == 0) continue;
                int c = line.IndexOf(',');
                values.Add(float.Parse(line.Substring(c + 1), CultureInfo.InvariantCulture));
            }
            return values.ToArray();
        }

        /// <summary>A centre as it appears in a file name: "-180", "7.5", never "-0".</summary>
        public static string CentreText(double deg)
        {
            return deg == 0.0 ? "0" : deg.ToString("R", CultureInfo.InvariantCulture);
        }

        public static string WindowFileName(double yawDeg, double pitchDeg)
        {
            return "horizontal_" + CentreText(yawDeg) + "_vertical_" + CentreText(pitchDeg) + ".csv";
        }

        /// <summary>Every window CSV of a folder and its percentile file (defaults without one).</summary>
        public static VimsimCao2021 LoadFolder(string dir)
        {
            var lists = new Dictionary<string, float[]>();
            var yaws = new SortedSet<double>();
            var pitches = new SortedSet<double>();
            foreach (var path in Directory.GetFiles(dir, "horizontal_*_vertical_*.csv"))
            {
                string name = Path.GetFileName(path);
                string[] parts = name.Substring(0, name.Length - 4).Split('_');
                yaws.Add(double.Parse(parts[1], CultureInfo.InvariantCulture));
                pitches.Add(double.Parse(parts[3], CultureInfo.InvariantCulture));
                lists[name] = ReadList(File.ReadAllText(path));
            }
            if (lists.Count == 0) throw new ArgumentException(dir + ": no window CSVs");
            var p = new List<double>(pitches);
            double pitchStep = p.Count > 1 ? p[1] - p[0] : 15.0;
            double lo = DefaultLowPx, hi = DefaultHighPx;
            string pct = Path.Combine(dir, "percentileData.csv");
            if (File.Exists(pct))
            {
                var v = new List<double>();
                foreach (var line in File.ReadAllText(pct).Split('\n'))
                    if (line.Trim().Length > 0) v.Add(double.Parse(line.Trim(), CultureInfo.InvariantCulture));
                lo = v[0]; hi = v[1];
            }
            return new VimsimCao2021(lists, 360.0 / yaws.Count, pitchStep, p[0], p[p.Count - 1], lo, hi);
        }

        static double Wrap180(double a)
        {
            double w = (a + 180.0) % 360.0;
            if (w < 0) w += 360.0;
            w -= 180.0;
            return w == -180.0 ? 180.0 : w;
        }

        /// <summary>The window centre their runtime reads for a pose (degrees).</summary>
        public static void NearestCentre(double yawDeg, double pitchDeg, double yawStep, double pitchStep,
                                         double pitchMin, double pitchMax, out double yawC, out double pitchC)
        {
            double yaw = Wrap180(yawDeg), pitch = Wrap180(pitchDeg), edge = 180.0 - yawStep;
            double up = Math.Ceiling(yaw / yawStep) * yawStep, dn = Math.Floor(yaw / yawStep) * yawStep;
            if (up > edge) up -= 360.0; else if (up < -edge) up += 360.0;
            if (dn > edge) dn -= 360.0; else if (dn < -edge) dn += 360.0;
            yawC = Math.Abs(yaw - up) <= Math.Abs(yaw - dn) ? up : dn;
            double pu = Math.Ceiling(pitch / pitchStep) * pitchStep, pd = Math.Floor(pitch / pitchStep) * pitchStep;
            pitchC = Math.Abs(pitch - pu) <= Math.Abs(pitch - pd) ? pu : pd;
            pitchC = Math.Min(Math.Max(pitchC, pitchMin), pitchMax);
        }

        /// <summary>Window px/frame their runtime uses at video frame k (0-based).</summary>
        public double Flow(int frame, double yawDeg, double pitchDeg)
        {
            double yc, pc;
            NearestCentre(yawDeg, pitchDeg, YawStepDeg, PitchStepDeg, PitchMinDeg, PitchMaxDeg, out yc, out pc);
            float[] list;
            if (!lists.TryGetValue(WindowFileName(yc, pc), out list))
                throw new KeyNotFoundException("no window file " + WindowFileName(yc, pc));
            int i = frame - 1;
            return (i < 0 || i >= list.Length) ? 0.0 : list[i];
        }

        public double Opacity(int frame, double yawDeg, double pitchDeg)
        {
            double o = (Flow(frame, yawDeg, pitchDeg) - LowPx) / (HighPx - LowPx);
            return o < 0 ? 0 : (o > 1 ? 1 : o);
        }
    }
}

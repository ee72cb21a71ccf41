import Foundation
import Monotrack

/// The per-frame cost of the benchmark's two paths, in milliseconds: the medians of the
/// `tracking/total` and `redetect/total` stages.
struct PathTotals: Equatable {
    /// One tracked frame (video mode: NCC search, face check, landmarks, flow, fit).
    let trackingMs: Double
    /// One re-detect frame (image mode: whole-frame detection, then landmarks and fit).
    let redetectMs: Double

    /// How many tracked frames one re-detect frame costs; nil when tracking measured no time.
    var ratio: Double? { trackingMs > 0 ? redetectMs / trackingMs : nil }
}

/// One of the benchmark's paths: its stages are named `<prefix>/<stage>`.
struct BenchPath: Identifiable {
    /// `tracking` or `redetect`.
    let prefix: String
    /// For display ("re-detect path").
    let title: String

    var id: String { prefix }
}

/// Turns a `BenchReport` into what the app shows and copies: the per-stage table of the thesis'
/// Tables 4.4/4.5 (median, p90 and mean in ms) and the per-frame totals of the tracking and
/// re-detect paths with their ratio.
///
/// The text is the same as the Android benchmark app's (`samples/android-bench`, `BenchSummary.kt`),
/// so reports from both platforms line up.
enum BenchSummary {
    /// Thesis, iPhone SE: milliseconds per tracked frame.
    static let thesisTrackingMs = 19.6
    /// Thesis, iPhone SE: milliseconds per frame with face detection.
    static let thesisDetectionMs = 525.6
    /// The benchmark's paths, in report order (the third: the tracking path with M3 in mirror-average mode).
    static let paths = [BenchPath(prefix: "tracking", title: "tracking path"),
                        BenchPath(prefix: "redetect", title: "re-detect path"),
                        BenchPath(prefix: "tracking_mirror_average", title: "tracking path, mirror-average landmarks")]

    /// Header of the stage column; the unit of every number column.
    private static let stageHeader = "stage, ms"
    /// Width of a number column in the text table.
    private static let columnWidth = 8

    /// The stage called `name` (`tracking/landmarks`, `redetect/total`, ...), or nil.
    static func stage(_ report: BenchReport, _ name: String) -> StageStat? {
        report.stages.first { $0.name == name }
    }

    /// The stages of one path, in the report's order.
    static func stages(_ report: BenchReport, path: BenchPath) -> [StageStat] {
        report.stages.filter { $0.name.hasPrefix(path.prefix + "/") }
    }

    /// The per-frame totals of both paths; nil when `tracking/total` or `redetect/total` is missing.
    static func totals(_ report: BenchReport) -> PathTotals? {
        guard let t = stage(report, "tracking/total"), let r = stage(report, "redetect/total") else { return nil }
        return PathTotals(trackingMs: t.medianUs / 1000, redetectMs: r.medianUs / 1000)
    }

    /// Whether the benchmark frame held a face (the report counts them).
    static func faceFound(_ report: BenchReport) -> Bool {
        report.faces > 0
    }

    /// Microseconds as milliseconds with two decimals ("3.38").
    static func ms(_ us: Double) -> String { String(format: "%.2f", us / 1000) }

    /// The stage table as monospace text: a header, then one line per stage with median, p90 and
    /// mean in ms.
    static func table(_ report: BenchReport) -> String {
        let width = max(stageHeader.count, report.stages.map(\.name.count).max() ?? 0)
        var out = row(stageHeader, ["median", "p90", "mean"], nameWidth: width)
        for s in report.stages {
            out += row(s.name, [ms(s.medianUs), ms(s.p90Us), ms(s.meanUs)], nameWidth: width)
        }
        return out
    }

    /// One line comparing the paths per frame, e.g.
    /// `per frame (median): tracking 3.38 ms, re-detect 4.08 ms, re-detect / tracking 1.21x`.
    static func totalsLine(_ report: BenchReport) -> String {
        guard let t = totals(report) else { return "per frame: the report has no total stages" }
        let ratio = t.ratio.map { String(format: "%.2fx", $0) } ?? "n/a"
        return String(format: "per frame (median): tracking %.2f ms, re-detect %.2f ms, re-detect / tracking ",
                      t.trackingMs, t.redetectMs) + ratio
    }

    /// The thesis' per-frame figures, for comparison under the measured ones.
    static func thesisLine() -> String {
        String(format: "thesis, iPhone SE: tracking %.1f ms, detection %.1f ms per frame (%.1fx)",
               thesisTrackingMs, thesisDetectionMs, thesisDetectionMs / thesisTrackingMs)
    }

    /// The text block for one benchmarked image: a title line (image, size, iterations and the SDK's
    /// device string), the stage table, a warning when no face was found, and the totals line.
    static func imageBlock(image: String, width: Int, height: Int, report: BenchReport) -> String {
        var out = "\(image) \(width)x\(height), \(report.iterations) iterations per path, \(report.device)\n"
        out += table(report)
        if !faceFound(report) {
            out += "no face found: the landmark and fit stages did not run, the paths are not comparable\n"
        }
        return out + totalsLine(report) + "\n"
    }

    /// A one-line reason for `error`: the SDK's message without the enum's decoration, or the
    /// wrapper's own description.
    static func describe(_ error: Error) -> String {
        switch error as? MonotrackError {
        case .InvalidFrame(let msg)?: return "invalid frame: \(msg)"
        case .InvalidTimestamp(let msg)?: return "invalid timestamp: \(msg)"
        case .InvalidState(let msg)?: return "invalid state: \(msg)"
        case .InvalidConfig(let msg)?: return "invalid configuration: \(msg)"
        case .ModelLoad(let msg)?: return "model load failed: \(msg)"
        case .BundleVersion(let msg)?: return "model bundle version: \(msg)"
        case .BundleChecksum(let msg)?: return "model bundle checksum: \(msg)"
        case .Io(let msg)?: return "i/o: \(msg)"
        case .Internal(let msg)?: return "internal error: \(msg)"
        case nil: return String(describing: error)
        }
    }

    /// `name` left-aligned in `nameWidth` columns, then each value right-aligned in a number column.
    private static func row(_ name: String, _ values: [String], nameWidth: Int) -> String {
        var line = name + String(repeating: " ", count: max(0, nameWidth - name.count))
        for v in values {
            line += " " + String(repeating: " ", count: max(0, columnWidth - v.count)) + v
        }
        return line + "\n"
    }
}

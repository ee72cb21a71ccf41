package io.monotrack.bench

import io.monotrack.BenchReport
import io.monotrack.MonotrackException
import io.monotrack.StageStat
import java.util.Locale

/**
 * The per-frame cost of the benchmark's two paths, in milliseconds: the medians of the
 * `tracking/total` and `redetect/total` stages.
 *
 * @property trackingMs one tracked frame (video mode: NCC search, face check, landmarks, flow, fit).
 * @property redetectMs one re-detect frame (image mode: whole-frame detection, then landmarks and fit).
 */
data class PathTotals(val trackingMs: Double, val redetectMs: Double) {
    /** How many tracked frames one re-detect frame costs; null when tracking measured no time. */
    val ratio: Double?
        get() = if (trackingMs > 0.0) redetectMs / trackingMs else null
}

/**
 * Turns a [BenchReport] into the text the app shows, copies, shares and logs: the per-stage table of
 * the thesis' Tables 4.4/4.5 (stage, median, p90 and mean in ms) followed by the per-frame totals of
 * the tracking and re-detect paths and their ratio.
 *
 * Plain Kotlin without `android.*` imports, so it is unit-tested on the JVM (`src/test`). The iOS
 * benchmark app (`samples/ios-bench`) writes the same text, so reports from both platforms line up.
 */
object BenchSummary {
    /** Thesis, iPhone SE: milliseconds per tracked frame. */
    const val THESIS_TRACKING_MS = 19.6

    /** Thesis, iPhone SE: milliseconds per frame with face detection. */
    const val THESIS_DETECTION_MS = 525.6

    /** Header of the stage column; the unit of every number column. */
    private const val STAGE_HEADER = "stage, ms"
    private const val US_PER_MS = 1000.0

    /** The stage called [name] (`tracking/landmarks`, `redetect/total`, ...), or null. */
    fun stage(report: BenchReport, name: String): StageStat? = report.stages.firstOrNull { it.name == name }

    /** The per-frame totals of both paths; null when `tracking/total` or `redetect/total` is missing. */
    fun totals(report: BenchReport): PathTotals? {
        val tracking = stage(report, "tracking/total") ?: return null
        val redetect = stage(report, "redetect/total") ?: return null
        return PathTotals(tracking.medianUs / US_PER_MS, redetect.medianUs / US_PER_MS)
    }

    /** Whether the benchmark frame held a face (the report counts them). */
    fun faceFound(report: BenchReport): Boolean = report.faces > 0u

    /** The stage table: a header, then one line per stage with median, p90 and mean in ms. */
    fun table(report: BenchReport): String {
        val nameWidth = maxOf(STAGE_HEADER.length, report.stages.maxOfOrNull { it.name.length } ?: 0)
        val sb = StringBuilder()
        sb.append(String.format(Locale.ROOT, "%-${nameWidth}s %8s %8s %8s\n", STAGE_HEADER, "median", "p90", "mean"))
        for (s in report.stages) {
            sb.append(
                String.format(
                    Locale.ROOT,
                    "%-${nameWidth}s %8.2f %8.2f %8.2f\n",
                    s.name,
                    s.medianUs / US_PER_MS,
                    s.p90Us / US_PER_MS,
                    s.meanUs / US_PER_MS,
                ),
            )
        }
        return sb.toString()
    }

    /**
     * One line comparing the paths per frame, e.g.
     * `per frame (median): tracking 3.38 ms, re-detect 4.08 ms, re-detect / tracking 1.21x`.
     */
    fun totalsLine(report: BenchReport): String {
        val t = totals(report) ?: return "per frame: the report has no total stages"
        val ratio = t.ratio?.let { String.format(Locale.ROOT, "%.2fx", it) } ?: "n/a"
        return String.format(
            Locale.ROOT,
            "per frame (median): tracking %.2f ms, re-detect %.2f ms, re-detect / tracking %s",
            t.trackingMs,
            t.redetectMs,
            ratio,
        )
    }

    /** The thesis' per-frame figures, for comparison under the measured ones. */
    fun thesisLine(): String = String.format(
        Locale.ROOT,
        "thesis, iPhone SE: tracking %.1f ms, detection %.1f ms per frame (%.1fx)",
        THESIS_TRACKING_MS,
        THESIS_DETECTION_MS,
        THESIS_DETECTION_MS / THESIS_TRACKING_MS,
    )

    /**
     * The block for one benchmarked image: a title line ([image], its size, iterations and the SDK's
     * device string), the stage table, a warning when no face was found, and the totals line.
     */
    fun imageBlock(image: String, width: Int, height: Int, report: BenchReport): String {
        val sb = StringBuilder()
        sb.append("$image ${width}x$height, ${report.iterations} iterations per path, ${report.device}, ")
        sb.append(String.format(Locale.ROOT, "models loaded in %.1f ms\n", report.modelLoadUs / 1000.0))
        sb.append(table(report))
        if (!faceFound(report)) {
            sb.append("no face found: the landmark and fit stages did not run, the paths are not comparable\n")
        }
        sb.append(totalsLine(report)).append('\n')
        return sb.toString()
    }

    /** A one-line reason for [e], without uniffi's `msg=` prefix. */
    fun describe(e: MonotrackException): String = when (e) {
        is MonotrackException.InvalidFrame -> "invalid frame: ${e.msg}"
        is MonotrackException.InvalidConfig -> "invalid configuration: ${e.msg}"
        is MonotrackException.InvalidTimestamp -> "invalid timestamp: ${e.msg}"
        is MonotrackException.InvalidState -> "invalid state: ${e.msg}"
        is MonotrackException.ModelLoad -> "model load failed: ${e.msg}"
        is MonotrackException.BundleVersion -> "model bundle version: ${e.msg}"
        is MonotrackException.BundleChecksum -> "model bundle checksum: ${e.msg}"
        is MonotrackException.Io -> "i/o: ${e.msg}"
        is MonotrackException.Internal -> "internal error: ${e.msg}"
    }
}

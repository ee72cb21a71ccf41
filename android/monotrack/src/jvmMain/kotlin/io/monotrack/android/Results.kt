// Pure Kotlin (no android.* imports): result helpers shared by apps, unit-tested on the JVM. They
// hold no rule of the SDK's: projections, default intrinsics and frame sizes come from the native
// library (`io.monotrack.headAxes`, `gazeArrows`, `projectPoint`, `defaultCamera`, `uprightSize`).
//
// Conventions (CONTRACT.md at the repository root): image coordinates in pixels of the upright,
// mirrored-as-asked frame, x right, y down, origin at the top-left corner of the top-left pixel;
// camera frame x right, y down, z forward, millimetres; the pose maps a head-frame point X to R·X + t.
package io.monotrack.android

import io.monotrack.BenchReport
import io.monotrack.CameraIntrinsics
import io.monotrack.Face
import io.monotrack.GazeArrows
import io.monotrack.Gestures
import io.monotrack.HeadAxes
import io.monotrack.HeadPose
import io.monotrack.TrackingResult
import java.util.Locale

private const val US_PER_MS = 1000.0

/**
 * The head's axes in the result image's pixels, [lengthMm] long, for a pose gizmo (the native
 * `headAxes`; [camera] is the result's `camera`).
 *
 * @return null when an end lies behind the camera.
 */
public fun HeadPose.axes(camera: CameraIntrinsics, lengthMm: Double): HeadAxes? =
    io.monotrack.headAxes(this, camera, lengthMm)

/** Each face's head axes in [TrackingResult]'s own camera, in face order (null where not drawable). */
public fun TrackingResult.headAxes(lengthMm: Double): List<HeadAxes?> = faces.map { it.pose.axes(camera, lengthMm) }

/**
 * Gaze arrows for drawing (the native `gazeArrows`): from each eye's centre along its gaze.
 *
 * @return null when the face carries no gaze (`outputGaze` off, or the ultra-light mode).
 */
public fun Face.gazeArrows(lengthPx: Float): GazeArrows? = gaze?.let { io.monotrack.gazeArrows(landmarks, it, lengthPx) }

/**
 * Copies the landmarks as x0, y0, x1, y1, … into [out] (for `Canvas.drawPoints`) without allocating.
 *
 * @return the number of floats written (2 × landmark count).
 * @throws IllegalArgumentException when [out] is too small.
 */
public fun Face.copyLandmarksTo(out: FloatArray): Int {
    require(out.size >= 2 * landmarks.size) { "need ${2 * landmarks.size} floats, got ${out.size}" }
    for ((i, p) in landmarks.withIndex()) {
        out[2 * i] = p.x
        out[2 * i + 1] = p.y
    }
    return 2 * landmarks.size
}

/** The most probable mouth gesture: "smile", "kiss" or "neutral", with its probability. */
public fun Gestures.mouth(): Pair<String, Float> =
    listOf("smile" to smile, "kiss" to kiss, "neutral" to mouthNeutral).maxBy { it.second }

/** The most probable brow gesture: "raise", "frown" or "neutral", with its probability. */
public fun Gestures.brows(): Pair<String, Float> =
    listOf("raise" to browRaise, "frown" to browFrown, "neutral" to browNeutral).maxBy { it.second }

/**
 * The per-stage table in the style of the thesis' Tables 4.4/4.5 (stage, median ms, p90 ms),
 * monospace-aligned, one stage per line after a header.
 */
public fun BenchReport.toTable(): String {
    val nameWidth = maxOf("stage".length, stages.maxOfOrNull { it.name.length } ?: 0)
    val sb = StringBuilder()
    sb.append(String.format(Locale.ROOT, "%-${nameWidth}s %10s %10s\n", "stage", "median ms", "p90 ms"))
    for (s in stages) {
        sb.append(
            String.format(
                Locale.ROOT,
                "%-${nameWidth}s %10.2f %10.2f\n",
                s.name,
                s.medianUs / US_PER_MS,
                s.p90Us / US_PER_MS,
            ),
        )
    }
    return sb.toString()
}

/**
 * Maps result-image pixels to view pixels for an image shown scaled to fill the view and centred
 * (CameraX `PreviewView.ScaleType.FILL_CENTER`, the default) or to fit inside it (FIT_CENTER).
 *
 * @property scale view pixels per image pixel.
 * @property offsetX view x of image x = 0.
 * @property offsetY view y of image y = 0.
 */
public data class ViewMapping(val scale: Float, val offsetX: Float, val offsetY: Float) {
    /** View x of image x. */
    public fun x(imageX: Float): Float = offsetX + scale * imageX

    /** View y of image y. */
    public fun y(imageY: Float): Float = offsetY + scale * imageY

    /** Maps [out]'s first [count] floats (x, y pairs) in place. */
    public fun mapPoints(out: FloatArray, count: Int) {
        var i = 0
        while (i + 1 < count) {
            out[i] = x(out[i])
            out[i + 1] = y(out[i + 1])
            i += 2
        }
    }

    public companion object {
        /**
         * The mapping for an image of [imageWidth]×[imageHeight] in a view of [viewWidth]×[viewHeight].
         *
         * @param fill true: cover the view, cropping (FILL_CENTER); false: fit inside it (FIT_CENTER).
         * @throws IllegalArgumentException when a size is not positive.
         */
        public fun centered(imageWidth: Int, imageHeight: Int, viewWidth: Int, viewHeight: Int, fill: Boolean): ViewMapping {
            require(imageWidth > 0 && imageHeight > 0 && viewWidth > 0 && viewHeight > 0) {
                "sizes must be positive: image ${imageWidth}x$imageHeight, view ${viewWidth}x$viewHeight"
            }
            val sx = viewWidth.toFloat() / imageWidth
            val sy = viewHeight.toFloat() / imageHeight
            val s = if (fill) maxOf(sx, sy) else minOf(sx, sy)
            return ViewMapping(s, (viewWidth - s * imageWidth) / 2f, (viewHeight - s * imageHeight) / 2f)
        }
    }
}

// Pure Kotlin (no android.* imports): result helpers shared by apps, unit-tested on the JVM.
//
// Conventions (CONTRACT.md at the repository root): image coordinates in pixels of the upright, mirrored-as-asked
// frame, x right, y down, origin at the top-left corner of the top-left pixel; camera frame x right,
// y down, z forward, millimetres; the pose maps a model point X to R·X + t.
package io.monotrack.android

import io.monotrack.BenchReport
import io.monotrack.CameraIntrinsics
import io.monotrack.Face
import io.monotrack.Gestures
import io.monotrack.HeadPose
import io.monotrack.MonotrackException
import io.monotrack.Point2
import io.monotrack.Vec3
import java.util.Locale

/** Number of landmarks in a [Face] (the 68-point iBUG / 300-W order). */
public const val LANDMARK_COUNT: Int = 68

/** Focal length in units of the larger image side when intrinsics are unknown (CONTRACT: about 58° FOV). */
public const val DEFAULT_FOCAL_PER_MAX_SIDE: Double = 0.9

/** iBUG indices of the subject's right eye contour (image left for a frontal face). */
public val RIGHT_EYE_INDICES: IntRange = 36..41

/** iBUG indices of the subject's left eye contour (image right for a frontal face). */
public val LEFT_EYE_INDICES: IntRange = 42..47

private const val ROTATION_ELEMENTS = 9
private const val US_PER_MS = 1000.0

/**
 * The intrinsics the SDK assumes when none are given (CONTRACT): fx = fy = 0.9 · max(width, height),
 * principal point at the image centre.
 */
public fun defaultIntrinsics(width: Int, height: Int): CameraIntrinsics {
    val f = DEFAULT_FOCAL_PER_MAX_SIDE * maxOf(width, height)
    return CameraIntrinsics(fx = f, fy = f, cx = width / 2.0, cy = height / 2.0)
}

/**
 * The rotation as a row-major 3×3 array.
 *
 * @throws MonotrackException.Internal when the record does not hold 9 finite values.
 */
public fun HeadPose.rotationMatrix(): DoubleArray {
    if (rotation.size != ROTATION_ELEMENTS || rotation.any { !it.isFinite() }) {
        throw MonotrackException.Internal("pose rotation has ${rotation.size} values, expected 9 finite")
    }
    return rotation.toDoubleArray()
}

/** Projects a camera-frame point (mm) to pixels; null when it lies on or behind the camera plane. */
public fun CameraIntrinsics.project(x: Double, y: Double, z: Double): Point2? {
    if (!(z > 0.0)) return null
    return Point2(x = (fx * x / z + cx).toFloat(), y = (fy * y / z + cy).toFloat())
}

/**
 * The head's model axes drawn from the model origin: [x] towards the subject's left, [y] down,
 * [z] away from the camera (the face model frame of CONTRACT), each [HeadPose.axes]' `lengthMm` long.
 *
 * @property origin the model origin in image pixels.
 * @property x tip of the model x axis.
 * @property y tip of the model y axis.
 * @property z tip of the model z axis.
 */
public data class HeadAxes(val origin: Point2, val x: Point2, val y: Point2, val z: Point2)

/**
 * Projects the head's model axes into the image, for drawing a pose gizmo.
 *
 * @param camera the intrinsics of the upright result image (use [defaultIntrinsics] with the
 *   result's `frameWidth`/`frameHeight` when the tracker was configured without `camera`).
 * @param lengthMm axis length in millimetres (a face is about 140 mm wide).
 * @return null when the pose puts any endpoint behind the camera.
 */
public fun HeadPose.axes(camera: CameraIntrinsics, lengthMm: Double): HeadAxes? {
    val r = rotationMatrix()
    val t = translationMm
    val origin = camera.project(t.x, t.y, t.z) ?: return null
    // Column j of R is model axis j expressed in the camera frame.
    fun tip(j: Int): Point2? = camera.project(
        t.x + lengthMm * r[j],
        t.y + lengthMm * r[3 + j],
        t.z + lengthMm * r[6 + j],
    )
    return HeadAxes(origin, tip(0) ?: return null, tip(1) ?: return null, tip(2) ?: return null)
}

/**
 * A 2D arrow in image pixels.
 *
 * @property from the tail (an eye centre for gaze arrows).
 * @property to the head.
 */
public data class Arrow(val from: Point2, val to: Point2)

/** The mean of the given landmarks. */
private fun Face.centroid(indices: IntRange): Point2 {
    var sx = 0f
    var sy = 0f
    for (i in indices) {
        sx += landmarks[i].x
        sy += landmarks[i].y
    }
    val n = (indices.last - indices.first + 1).toFloat()
    return Point2(x = sx / n, y = sy / n)
}

/**
 * Gaze arrows for drawing: from each eye's landmark centroid along the gaze direction's image-plane
 * component, [lengthPx] long for a gaze perpendicular to the optical axis (an orthographic sketch:
 * enough for an overlay, not a measurement).
 *
 * @return (subject's right eye, subject's left eye), or null when the face lacks 68 landmarks or
 *   carries no gaze (`TrackerConfig.gaze` off, or the ultra-light mode).
 */
public fun Face.gazeArrows(lengthPx: Float): Pair<Arrow, Arrow>? {
    val gaze = gaze ?: return null
    if (landmarks.size != LANDMARK_COUNT) return null
    fun arrow(eye: Point2, g: Vec3) = Arrow(
        eye,
        Point2(x = eye.x + lengthPx * g.x.toFloat(), y = eye.y + lengthPx * g.y.toFloat()),
    )
    return arrow(centroid(RIGHT_EYE_INDICES), gaze.right) to arrow(centroid(LEFT_EYE_INDICES), gaze.left)
}

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

/** The most probable mouth gesture: "smile", "frown", "kiss" or "neutral", with its probability. */
public fun Gestures.mouth(): Pair<String, Float> =
    listOf("smile" to smile, "frown" to frown, "kiss" to kiss, "neutral" to mouthNeutral).maxBy { it.second }

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

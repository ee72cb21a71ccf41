package io.monotrack.android

import androidx.camera.core.ImageProxy
import io.monotrack.FaceTracker
import io.monotrack.MonotrackException
import io.monotrack.TrackingResult

/** CameraX's nanosecond sensor time in the tracker's milliseconds. */
private const val NS_PER_MS = 1_000_000L

/**
 * Image mode: the faces of a CameraX frame, read in place (plane 0, Y, passed as a
 * [io.monotrack.PixelFormat.GRAY8] frame with its row stride and the image's `rotationDegrees`; no
 * pixel is copied on the Kotlin side). The caller keeps ownership of [image] and closes it after
 * this returns.
 *
 * @param mirrored true for the front camera, so that results match the mirrored preview.
 * @throws MonotrackException.InvalidFrame when the image is not YUV_420_888 or its planes are inconsistent.
 * @throws MonotrackException.InvalidState when the tracker is not in the image mode or was shut down.
 */
public fun FaceTracker.detect(image: ImageProxy, mirrored: Boolean): TrackingResult {
    val frame = image.lumaFrame(mirrored)
    return detect(frame.bytes, frame.desc)
}

/**
 * Video mode: the faces of a CameraX frame (as [detect]), tracked from the frames before, at the
 * frame's sensor time.
 *
 * @throws MonotrackException.InvalidTimestamp when the frame's time is not after the previous
 *   frame's (a restarted camera: call `reset()`).
 * @throws MonotrackException.InvalidFrame when the image is not YUV_420_888 or its planes are inconsistent.
 * @throws MonotrackException.InvalidState when the tracker is not in the video mode or was shut down.
 */
public fun FaceTracker.detectForVideo(image: ImageProxy, mirrored: Boolean): TrackingResult {
    val frame = image.lumaFrame(mirrored)
    return detectForVideo(frame.bytes, frame.desc, image.imageInfo.timestamp / NS_PER_MS)
}

/**
 * Live-stream mode: hands a CameraX frame (as [detect]) to the tracker's worker and returns at once
 * (the bytes are copied, so [image] may be closed on return); its result reaches the listener.
 *
 * @return true when a frame still waiting was replaced by this one.
 * @throws MonotrackException.InvalidTimestamp as [detectForVideo].
 * @throws MonotrackException.InvalidState when the tracker is not in the live-stream mode or was shut down.
 */
public fun FaceTracker.detectAsync(image: ImageProxy, mirrored: Boolean): Boolean {
    val frame = image.lumaFrame(mirrored)
    return detectAsync(frame.bytes, frame.desc, image.imageInfo.timestamp / NS_PER_MS)
}

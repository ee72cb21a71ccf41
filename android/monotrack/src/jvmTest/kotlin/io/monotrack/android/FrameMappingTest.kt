package io.monotrack.android

import io.monotrack.MonotrackException
import io.monotrack.PixelFormat
import io.monotrack.uprightSize
import org.junit.jupiter.api.Assertions.assertEquals
import org.junit.jupiter.api.Assertions.assertThrows
import org.junit.jupiter.api.Test

class FrameMappingTest {
    @Test
    fun lumaPlaneWithPaddedRowsMapsToGray8WithItsStride() {
        // A 640x480 Y plane padded to 704 bytes per row, last row unpadded (as many HALs deliver).
        val size = 704 * 479 + 640
        val d = FrameMapping.lumaFrameDesc(640, 480, PlaneLayout(704, 1, size), 270, mirrored = true)
        assertEquals(PixelFormat.GRAY8, d.format)
        assertEquals(640u, d.width)
        assertEquals(480u, d.height)
        assertEquals(704u, d.rowStride)
        assertEquals(270u, d.rotationDegrees)
        assertEquals(true, d.mirrored)
        assertEquals(0u, d.uvRowStride)
    }

    @Test
    fun lumaPlaneTooShortIsInvalidFrame() {
        val e = assertThrows(MonotrackException.InvalidFrame::class.java) {
            FrameMapping.lumaFrameDesc(640, 480, PlaneLayout(704, 1, 704 * 479 + 639), 0, false)
        }
        assert(e.msg.contains("needs")) { e.msg }
    }

    @Test
    fun lumaStrideBelowWidthOrPixelStrideNotOneIsInvalidFrame() {
        assertThrows(MonotrackException.InvalidFrame::class.java) {
            FrameMapping.lumaFrameDesc(640, 480, PlaneLayout(600, 1, 1 shl 20), 0, false)
        }
        assertThrows(MonotrackException.InvalidFrame::class.java) {
            FrameMapping.lumaFrameDesc(640, 480, PlaneLayout(1280, 2, 1 shl 21), 0, false)
        }
        assertThrows(MonotrackException.InvalidFrame::class.java) {
            FrameMapping.lumaFrameDesc(0, 480, PlaneLayout(640, 1, 1 shl 20), 0, false)
        }
    }

    @Test
    fun rotationsNormaliseAndRejectNonQuarterTurns() {
        assertEquals(0, FrameMapping.normalizeRotation(0))
        assertEquals(90, FrameMapping.normalizeRotation(450))
        assertEquals(270, FrameMapping.normalizeRotation(-90))
        assertEquals(180, FrameMapping.normalizeRotation(-540))
        assertThrows(MonotrackException.InvalidFrame::class.java) { FrameMapping.normalizeRotation(45) }
    }

    @Test
    fun theNativeUprightSizeSwapsForQuarterTurns() {
        val plane = PlaneLayout(640, 1, 640 * 480)
        for ((rot, want) in listOf(90 to (480u to 640u), 270 to (480u to 640u), 180 to (640u to 480u))) {
            val s = uprightSize(FrameMapping.lumaFrameDesc(640, 480, plane, rot, false))
            assertEquals(want, s.width to s.height, "rotation $rot")
        }
    }

    @Test
    fun rgbaBitmapMapsWithDefaultTightStride() {
        val d = FrameMapping.rgbaFrameDesc(width = 512, height = 512, sizeBytes = 512 * 512 * 4)
        assertEquals(PixelFormat.RGBA8, d.format)
        assertEquals(2048u, d.rowStride)
        assertThrows(MonotrackException.InvalidFrame::class.java) {
            FrameMapping.rgbaFrameDesc(width = 512, height = 512, sizeBytes = 512 * 512 * 4 - 1)
        }
    }
}

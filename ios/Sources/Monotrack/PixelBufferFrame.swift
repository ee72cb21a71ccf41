// CoreVideo exists on Apple platforms only: on Linux (bindings/tests/run-swift.sh) this file is empty.
#if canImport(CoreVideo)
import CoreVideo
import Foundation
import MonotrackFFI

extension CVPixelBuffer {
    /// Calls `body` with this buffer's pixels as `Data` and the matching `FrameDesc`, with the base
    /// address locked read-only for exactly the duration of the call.
    ///
    /// BGRA buffers are passed as `.bgra8` with `bytesPerRow`; NV12 buffers (`'420f'`, `'420v'`, the
    /// camera's native formats) as their luma plane alone, `.gray8` with `bytesPerRowOfPlane(0)`;
    /// 8-bit gray (`'L008'`) as `.gray8`. The `Data` wraps the locked memory without copying and must
    /// not escape `body`.
    ///
    /// - Parameter orientation: how to make the buffer upright (see `FrameOrientation`).
    /// - Throws: `FrameError` when the format is unsupported or the buffer cannot be locked;
    ///   `MonotrackError.InvalidFrame` when its sizes and stride describe no frame
    ///   (`frameByteCount`); whatever `body` throws.
    public func withMonotrackFrame<R>(
        orientation: FrameOrientation, _ body: (Data, FrameDesc) throws -> R
    ) throws -> R {
        let choice = try FrameLayout.choice(for: CVPixelBufferGetPixelFormatType(self))
        let status = CVPixelBufferLockBaseAddress(self, .readOnly)
        guard status == kCVReturnSuccess else { throw FrameError.lockFailed(status) }
        defer { CVPixelBufferUnlockBaseAddress(self, .readOnly) }

        let base: UnsafeMutableRawPointer?
        let width: Int, height: Int, bytesPerRow: Int
        if choice.planar {
            base = CVPixelBufferGetBaseAddressOfPlane(self, choice.plane)
            width = CVPixelBufferGetWidthOfPlane(self, choice.plane)
            height = CVPixelBufferGetHeightOfPlane(self, choice.plane)
            bytesPerRow = CVPixelBufferGetBytesPerRowOfPlane(self, choice.plane)
        } else {
            base = CVPixelBufferGetBaseAddress(self)
            width = CVPixelBufferGetWidth(self)
            height = CVPixelBufferGetHeight(self)
            bytesPerRow = CVPixelBufferGetBytesPerRow(self)
        }
        guard let base else { throw FrameError.noBaseAddress }
        let (desc, count) = try FrameLayout.describe(
            choice, width: width, height: height, bytesPerRow: bytesPerRow, orientation: orientation)
        let data = Data(bytesNoCopy: base, count: count, deallocator: .none)
        return try body(data, desc)
    }
}
#endif

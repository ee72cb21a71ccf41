import Foundation
import MonotrackFFI
#if canImport(CoreMedia)
import AVFoundation
import CoreMedia
import simd
#endif

/// Camera intrinsics for `FaceTrackerOptions.camera`. The SDK wants them for the buffer as delivered
/// (before rotation and mirroring), in that buffer's pixels; it turns them with each frame.
extension CameraIntrinsics {
    #if canImport(CoreMedia)
    /// The intrinsic matrix the camera attaches to a frame, already in the buffer's pixels. Attached
    /// when `AVCaptureConnection.isCameraIntrinsicMatrixDeliveryEnabled` is on (check
    /// `isCameraIntrinsicMatrixDeliverySupported` first); `nil` otherwise.
    public init?(sampleBuffer: CMSampleBuffer) {
        guard let data = CMGetAttachment(sampleBuffer, key: kCMSampleBufferAttachmentKey_CameraIntrinsicMatrix,
                                         attachmentModeOut: nil) as? Data,
              data.count >= MemoryLayout<matrix_float3x3>.size
        else { return nil }
        let m = data.withUnsafeBytes { $0.loadUnaligned(as: matrix_float3x3.self) }
        // Column-major: columns[2] holds the principal point.
        let (fx, fy, cx, cy) = (Double(m.columns.0.x), Double(m.columns.1.y), Double(m.columns.2.x), Double(m.columns.2.y))
        guard fx > 0, fy > 0, fx.isFinite, fy.isFinite, cx.isFinite, cy.isFinite else { return nil }
        self.init(fx: fx, fy: fy, cx: cx, cy: cy)
    }
    #endif

    /// Intrinsics for a horizontal field of view of `fieldOfViewDegrees` across a `width`×`height`
    /// buffer, principal point centred (for example from `AVCaptureDevice.activeFormat.videoFieldOfView`
    /// when the device attaches no matrix). `nil` for a field of view outside (0, 180) or an empty size.
    public init?(fieldOfViewDegrees: Double, width: Int, height: Int) {
        guard fieldOfViewDegrees > 0, fieldOfViewDegrees < 180, width > 0, height > 0 else { return nil }
        let f = Double(width) / 2 / tan(fieldOfViewDegrees * .pi / 360)
        self.init(fx: f, fy: f, cx: Double(width) / 2, cy: Double(height) / 2)
    }
}

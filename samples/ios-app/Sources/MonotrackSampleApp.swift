import SwiftUI

/// Front camera with the tracker's landmarks, head axes, gaze and gestures drawn on top.
@main
struct MonotrackSampleApp: App {
    var body: some Scene {
        WindowGroup { ContentView() }
    }
}

// One Gradle build for the SDK library and both sample apps, so the apps always use the library
// built from this checkout (project dependency), never a stale published AAR.
pluginManagement {
    repositories {
        google()
        mavenCentral()
        gradlePluginPortal()
    }
}

dependencyResolutionManagement {
    repositoriesMode.set(RepositoriesMode.FAIL_ON_PROJECT_REPOS)
    repositories {
        google()
        mavenCentral()
    }
}

rootProject.name = "monotrack-android"

include(":monotrack")
include(":android-app")
project(":android-app").projectDir = file("../samples/android-app")
include(":android-bench")
project(":android-bench").projectDir = file("../samples/android-bench")

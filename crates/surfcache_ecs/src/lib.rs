//! bevy_ecs components, resources and systems.

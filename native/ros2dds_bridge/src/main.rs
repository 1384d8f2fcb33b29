//! A Zenoh router running zenoh-plugin-ros2dds statically, like zenoh-bridge-ros2dds.
//!
//! Usage: `skinet-ros2dds-bridge -c CONFIG.json5`. The whole configuration is the file:
//! `mode`, `listen`/`connect` and `plugins.ros2dds` (`domain`, `namespace`, `allow`...).
use zenoh::internal::{plugins::PluginsManager, runtime::RuntimeBuilder};
use zenoh_plugin_trait::Plugin;

fn fail(what: &str, error: impl std::fmt::Display) -> ! {
    eprintln!("skinet-ros2dds-bridge: {what}: {error}");
    std::process::exit(1)
}

#[tokio::main]
async fn main() {
    zenoh::init_log_from_env_or("warn");
    let args: Vec<String> = std::env::args().collect();
    let path = match args.as_slice() {
        [_, flag, path] if flag == "-c" || flag == "--config" => path,
        _ => fail("usage", "skinet-ros2dds-bridge -c CONFIG.json5"),
    };
    let mut config = zenoh::Config::from_file(path).unwrap_or_else(|e| fail(path, e));
    // The plugin caches TRANSIENT_LOCAL topics, which needs timestamps.
    for (key, value) in [("timestamping/enabled", "true"), ("plugins_loading/enabled", "true")] {
        config.insert_json5(key, value).unwrap_or_else(|e| fail(key, e));
    }
    let mut plugins = PluginsManager::static_plugins_only();
    plugins.declare_static_plugin::<zenoh_plugin_ros2dds::ROS2Plugin, &str>("ros2dds", true);
    let mut runtime = RuntimeBuilder::new(config).plugins_manager(plugins).build().await
        .unwrap_or_else(|e| fail("runtime", e));
    runtime.start().await.unwrap_or_else(|e| fail("start", e));
    println!("zenoh-plugin-ros2dds {} running", zenoh_plugin_ros2dds::ROS2Plugin::PLUGIN_VERSION);
    std::future::pending::<()>().await
}

// servoamp live view: renders Foxglove Studio's App (exposed on window by the
// prebuilt UMD build of @foxglove/studio-base, see index.html) with in-memory
// app settings and layout storage, the servoamp layout, and a Foxglove
// WebSocket connection. Query string:
//   url=ws://127.0.0.1:8765/?token=...   the Foxglove WebSocket URL (required)
//   layout=../foxglove/servoamp-layout.json   the layout to load (this default
//                                             when the tools/ folder is served)
// Progress for a driver: window.servoampViewer = {state, error, layoutName}.

const { App, AppSetting, FoxgloveWebSocketDataSourceFactory, initI18n, waitForFonts } = window;
const React = window.React;
const ReactDOM = window.ReactDOM;

const LAYOUT_ID = "servoamp";
const status = (window.servoampViewer = { state: "starting", error: undefined, layoutName: undefined });

/** IAppConfiguration in memory: nothing persists across page loads. */
class MemoryAppConfiguration {
  constructor(values) {
    this.values = new Map(Object.entries(values));
    this.listeners = new Map();
  }
  get(key) {
    return this.values.get(key);
  }
  async set(key, value) {
    this.values.set(key, value);
    for (const cb of [...(this.listeners.get(key) ?? [])]) cb(value);
  }
  addChangeListener(key, cb) {
    if (!this.listeners.has(key)) this.listeners.set(key, new Set());
    this.listeners.get(key).add(cb);
  }
  removeChangeListener(key, cb) {
    this.listeners.get(key)?.delete(cb);
  }
}

/** ILayoutStorage in memory, by namespace. */
class MemoryLayoutStorage {
  constructor() {
    this.byNamespace = new Map();
  }
  ns(namespace) {
    if (!this.byNamespace.has(namespace)) this.byNamespace.set(namespace, new Map());
    return this.byNamespace.get(namespace);
  }
  async list(namespace) {
    return [...this.ns(namespace).values()];
  }
  async get(namespace, id) {
    return this.ns(namespace).get(id);
  }
  async put(namespace, layout) {
    this.ns(namespace).set(layout.id, layout);
    return layout;
  }
  async delete(namespace, id) {
    this.ns(namespace).delete(id);
  }
  async importLayouts({ fromNamespace, toNamespace }) {
    for (const l of await this.list(fromNamespace)) await this.put(toNamespace, l);
  }
}

async function main() {
  const params = new URLSearchParams(window.location.search);
  const wsUrl = params.get("url") ?? params.get("ds.url");
  if (!wsUrl) throw new Error("no Foxglove WebSocket URL: add ?url=ws://HOST:PORT/ to the page's address");
  const layoutUrl = new URL(params.get("layout") ?? "../foxglove/servoamp-layout.json", window.location.href);
  const resp = await fetch(layoutUrl);
  if (!resp.ok) throw new Error(`layout ${layoutUrl}: HTTP ${resp.status}`);
  const data = await resp.json();

  const layoutStorage = new MemoryLayoutStorage();
  // LayoutManager keeps local layouts in the "local" namespace (LayoutManager.LOCAL_STORAGE_NAMESPACE)
  await layoutStorage.put("local", {
    id: LAYOUT_ID,
    name: "servoamp",
    permission: "CREATOR_WRITE",
    baseline: { data, savedAt: new Date().toISOString() },
    working: undefined,
    syncInfo: undefined,
  });
  status.layoutName = "servoamp";

  const appConfiguration = new MemoryAppConfiguration({
    [AppSetting.COLOR_SCHEME]: "light",
    [AppSetting.TIMEZONE]: "UTC",
    [AppSetting.SHOW_OPEN_DIALOG_ON_STARTUP]: false,
    [AppSetting.TELEMETRY_ENABLED]: false,
    [AppSetting.CRASH_REPORTING_ENABLED]: false,
    [AppSetting.UPDATES_ENABLED]: false,
    [AppSetting.HIDE_SIGN_IN_PROMPT]: true,
    [AppSetting.LAUNCH_PREFERENCE]: "web",
  });

  // Studio reads its start-up state (data source, layout) from the page's own
  // address, in its deep-link form: ds=foxglove-websocket&ds.url=...&layoutId=...
  const deepLink = new URL(window.location.href);
  for (const k of [...deepLink.searchParams.keys()]) deepLink.searchParams.delete(k);
  deepLink.searchParams.set("ds", "foxglove-websocket");
  deepLink.searchParams.set("ds.url", wsUrl);
  deepLink.searchParams.set("layoutId", LAYOUT_ID);
  if (params.has("layout")) deepLink.searchParams.set("layout", params.get("layout"));
  window.history.replaceState(undefined, "", deepLink.href);

  await waitForFonts();
  await initI18n();
  ReactDOM.render(
    React.createElement(App, {
      deepLinks: [deepLink.href],
      appConfiguration,
      layoutStorage,
      dataSources: [new FoxgloveWebSocketDataSourceFactory()],
      extensionLoaders: [],
      enableGlobalCss: true,
    }),
    document.getElementById("root"),
  );
  status.state = "rendered";
}

main().catch((err) => {
  status.state = "failed";
  status.error = String(err?.stack ?? err);
  console.error(err);
  document.getElementById("root").textContent = `servoamp viewer: ${err}`;
});

// The viewer's decoder and client state: crates/psao-wasm compiled to WebAssembly
// (`web/build-wasm.sh` → `dist/psao.wasm`, served at `/psao.wasm`), the same Rust as
// `psao view`'s psao-delta decoder and psao-client state. This file only moves bytes across
// its C ABI (crates/psao-wasm/src/abi.rs) and reads what it leaves in wasm memory.
import type { InstanceEntry } from "./wire";

/// Numbers per instance of the table handed to the wasm (crates/psao-wasm/src/table.rs).
const TABLE_WORDS = 11;

/// The module's exports (crates/psao-wasm/src/abi.rs); pointers and lengths are numbers.
interface Exports {
  memory: WebAssembly.Memory;
  psao_alloc(len: number): number;
  psao_free(ptr: number, len: number): void;
  psao_viewer_new(table: number, len: number): number;
  psao_viewer_free(handle: number): void;
  psao_table_status(handle: number): number;
  psao_apply(handle: number, payload: number, len: number, snapshot: number): number;
  psao_error_ptr(handle: number): number;
  psao_error_len(handle: number): number;
  psao_state_hash(handle: number): bigint;
  psao_has_lights(handle: number): number;
  psao_changes_ptr(handle: number): number;
  psao_changes_len(handle: number): number;
  psao_instance_count(handle: number): number;
  psao_bucket_count(handle: number, instance: number): number;
  psao_max_cells(handle: number, instance: number): number;
  psao_slot_count(handle: number, instance: number): number;
  psao_point_count(handle: number): number;
  psao_transform(handle: number, instance: number): number;
}

/// A table or update the Rust side refused; `code` is its status (crates/psao-wasm `ViewerError::code`).
export class DecodeError extends Error {
  constructor(
    message: string,
    readonly code: number,
  ) {
    super(message);
  }
}

/// The instantiated module; one per page (or Node process), any number of states.
export class Codec {
  private constructor(readonly exports: Exports) {}

  /// Instantiates the module from its bytes or a fetch of them.
  static async load(source: BufferSource | Promise<Response>): Promise<Codec> {
    const { instance } =
      source instanceof Promise
        ? await WebAssembly.instantiateStreaming(source)
        : await WebAssembly.instantiate(source);
    return new Codec(instance.exports as unknown as Exports);
  }

  /// Copies `bytes` into a fresh wasm buffer; the caller frees it.
  put(bytes: Uint8Array): number {
    const ptr = this.exports.psao_alloc(bytes.length);
    new Uint8Array(this.exports.memory.buffer, ptr, bytes.length).set(bytes);
    return ptr;
  }
}

/// One session's decoder and client state (psao-client's `ClientState`, its state hash).
export class ViewerState {
  private handle: number;
  private cached: (Float32Array | null)[] = [];
  private transformsStale = true;

  /// An empty state for the welcome's table; a table the Rust client refuses throws.
  constructor(
    private codec: Codec,
    /// The welcome's instance table.
    readonly table: InstanceEntry[],
  ) {
    const words = new Float64Array(table.length * TABLE_WORDS);
    table.forEach((e, k) =>
      words.set(
        [...e.origin, e.cellSize, ...e.dims, e.layoutPoissonRadius, e.bucketCount, e.poissonRadius, e.pointCount],
        k * TABLE_WORDS,
      ),
    );
    const bytes = new Uint8Array(words.buffer);
    const x = codec.exports;
    const ptr = codec.put(bytes);
    this.handle = x.psao_viewer_new(ptr, bytes.length);
    x.psao_free(ptr, bytes.length);
    const status = x.psao_table_status(this.handle);
    if (status !== 0) {
      const text = this.error();
      this.free();
      throw new DecodeError(text, status);
    }
  }

  /// Decodes and applies one update payload (`snapshot`: its message was a snapshot); throws
  /// a DecodeError (the session must then end).
  apply(payload: Uint8Array, snapshot: boolean) {
    const x = this.codec.exports;
    const ptr = this.codec.put(payload);
    const status = x.psao_apply(this.handle, ptr, payload.length, snapshot ? 1 : 0);
    x.psao_free(ptr, payload.length);
    this.transformsStale = true;
    if (status !== 0) throw new DecodeError(this.error(), status);
  }

  /// Every instance's transform from the latest update carrying one (Affine3A: columns x, y,
  /// z, then translation, 12 floats), or null; read from the wasm once per applied update.
  get transforms(): readonly (Float32Array | null)[] {
    if (this.transformsStale) {
      this.transformsStale = false;
      this.cached = Array.from({ length: this.instanceCount() }, (_, i) => this.transform(i));
    }
    return this.cached;
  }

  /// psao-client's state hash (compared with the server's).
  stateHash(): bigint {
    return BigInt.asUintN(64, this.codec.exports.psao_state_hash(this.handle));
  }

  /// Whether the state holds irradiance records (the server computes lighting).
  hasLights(): boolean {
    return this.codec.exports.psao_has_lights(this.handle) !== 0;
  }

  /// What the last update changed, as crates/psao-wasm/src/changes.rs lays it out: a view of
  /// wasm memory, valid until the next call on this state.
  changes(): Uint32Array {
    const x = this.codec.exports;
    return new Uint32Array(x.memory.buffer, x.psao_changes_ptr(this.handle), x.psao_changes_len(this.handle));
  }

  /// Instances in the table.
  instanceCount(): number {
    return this.codec.exports.psao_instance_count(this.handle);
  }

  /// Hash buckets of an instance's grid, 0 when it has none (an unusable layout).
  bucketCount(instance: number): number {
    return this.codec.exports.psao_bucket_count(this.handle, instance);
  }

  /// Cell slots an instance's layout addresses (0 without a grid).
  maxCells(instance: number): number {
    return this.codec.exports.psao_max_cells(this.handle, instance);
  }

  /// Cell slots an instance's grid has allocated (0 without a grid).
  slotCount(instance: number): number {
    return this.codec.exports.psao_slot_count(this.handle, instance);
  }

  /// Valid points over all grids.
  pointCount(): number {
    return this.codec.exports.psao_point_count(this.handle);
  }

  private transform(instance: number): Float32Array | null {
    const x = this.codec.exports;
    const ptr = x.psao_transform(this.handle, instance);
    return ptr === 0 ? null : new Float32Array(x.memory.buffer, ptr, 12).slice();
  }

  /// Frees the wasm side (the state is unusable afterwards).
  free() {
    if (this.handle !== 0) this.codec.exports.psao_viewer_free(this.handle);
    this.handle = 0;
  }

  private error(): string {
    const x = this.codec.exports;
    const bytes = new Uint8Array(x.memory.buffer, x.psao_error_ptr(this.handle), x.psao_error_len(this.handle));
    return new TextDecoder().decode(bytes);
  }
}

import type { StoreApi } from 'zustand/vanilla';
import type { CommandDecl } from '../../fleet/commands';
import { KernelSession } from '../../fleet/kernel';
import type { DuetClient } from './client';
import { uploadCommandFor, type DuetCommands, type FileArgs } from './commands';
import { DEFAULT_HEIGHT_MAP, dirKey, type DuetReads } from './reads';
import type { DuetState } from './state';
import type { DuetUploads } from './uploads';
import type { DirEntry, HeightMap, ParsedFileInfo } from './wire';

/**
 * What the Duet's views call on its session beyond the link: files, uploads, the height map and
 * the message boxes shown. The session (session.ts) owns the parts; this reads them.
 */
export abstract class DuetPageApi extends KernelSession {
  abstract readonly client: DuetClient;
  abstract readonly store: StoreApi<DuetState>;
  abstract readonly reads: DuetReads;
  abstract readonly cmd: DuetCommands;
  protected abstract readonly uploads: DuetUploads;
  /** A read that renews a dead session once (session.ts). */
  protected abstract read<T>(fn: (signal: AbortSignal) => Promise<T>, signal: AbortSignal): Promise<T>;

  /** Which upload command applies to a directory (operator only into the jobs folder). */
  uploadCommandFor(dir: string): CommandDecl<FileArgs> {
    return uploadCommandFor(this.cmd, dir);
  }

  cancelUpload(id: number): void {
    this.uploads.cancel(id);
  }

  /** Shows `dir` in the Files tab (its listing is a query the tab reads). */
  openDir(dir: string): void {
    this.store.setState({ filesDir: dir });
  }

  /** Shows `dir` and reads its listing (cached for DIR_STALE_MS). */
  loadDir(dir: string): Promise<DirEntry[]> {
    this.openDir(dir);
    return this.reads.listDir(dir);
  }

  /** Reads the shown folder again. */
  refreshDir(): Promise<void> {
    return this.ctx.queries.invalidate(dirKey(this.store.getState().filesDir));
  }

  loadFileInfo(path: string): Promise<ParsedFileInfo> {
    return this.reads.loadFileInfo(path);
  }

  /** The height map `move.compensation.file` names (default `0:/sys/heightmap.csv`). */
  heightMapPath(): string {
    return this.store.getState().model?.move.compensation?.file ?? DEFAULT_HEIGHT_MAP;
  }

  loadHeightMap(): Promise<HeightMap> {
    return this.reads.loadHeightMap(this.heightMapPath());
  }

  download(path: string): Promise<Blob> {
    return this.read((signal) => this.client.download(path, signal), this.signal);
  }

  dismissBox(seq: number): void {
    this.store.setState((s) => ({ dismissedBoxes: [...s.dismissedBoxes.slice(-20), seq] }));
  }

  /** Show a hidden message box again. */
  reopenBox(seq: number): void {
    this.store.setState((s) => ({ dismissedBoxes: s.dismissedBoxes.filter((d) => d !== seq) }));
  }
}

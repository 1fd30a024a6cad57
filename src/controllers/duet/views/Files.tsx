import { useRef, useState, type ReactNode } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { LinkError } from '../../../fleet/errors';
import { CommandButton, useCan, useSnapshot, useStoreSelect } from '../../../fleet/react';
import { Button, Dialog, Field, Notice, Panel, ProgressBar, formatBytes, formatDateTime } from '../../../ui';
import { openToViewers } from '../access';
import { joinPath } from '../client';
import type { DuetSession } from '../session';
import type { DirEntry } from '../wire';
import { DuetFrame, Thumbnail } from './common';
import { useDirectory, useFileInfo } from './reads';

type Root = 'gCodes' | 'macros' | 'system' | 'filaments';
const ROOTS: Array<[Root, string]> = [
  ['gCodes', 'Jobs'],
  ['macros', 'Macros'],
  ['system', 'System'],
  ['filaments', 'Filaments'],
];

function trimDir(d: string): string {
  return d.length > 3 && d.endsWith('/') ? d.slice(0, -1) : d;
}

/** Files: the folders named in `directories`, upload/download, delete, rename/move, new folder, job start, macros. */
export function Files({ session }: TabProps<DuetSession>) {
  const ctx = session.ctx;
  const dirs = useStoreSelect(session.store, (s) => s.model?.directories ?? null);
  const shownDir = useStoreSelect(session.store, (s) => s.filesDir);
  const uploads = useStoreSelect(session.store, (s) => s.uploads);
  const link = useSnapshot(ctx, (s) => s.link);
  const canSupervise = useCan('supervisor');
  const [root, setRoot] = useState<Root>('gCodes');
  const [rename, setRename] = useState<DirEntry | null>(null);
  const [newFolder, setNewFolder] = useState(false);
  const [error, setError] = useState<string | null>(null);
  const fileInput = useRef<HTMLInputElement>(null);

  const rootDir = trimDir(dirs?.[root] ?? '0:/gcodes');
  const dir = shownDir.startsWith(rootDir) ? shownDir : rootDir;
  // The listing is a query of the machine: cached, read again after file commands (reads.ts).
  const files = useDirectory(session, dir, link === 'online');

  const open = (d: string) => session.openDir(d);
  const up = dir !== rootDir ? dir.slice(0, dir.lastIndexOf('/')) : null;
  const uploadCmd = session.uploadCommandFor(dir);
  const canUpload = useCan(uploadCmd.role);

  const onFiles = async (list: FileList | null) => {
    if (!list) return;
    setError(null);
    for (const f of Array.from(list)) {
      try {
        await ctx.commands.run(uploadCmd, { file: f, name: f.name, dir });
      } catch (e) {
        setError(e instanceof Error ? e.message : String(e));
        if (e instanceof LinkError && e.kind === 'aborted') continue;
      }
    }
    if (fileInput.current) fileInput.current.value = '';
  };

  const download = async (path: string, name: string) => {
    try {
      const blob = await session.download(path);
      const url = URL.createObjectURL(blob);
      const a = document.createElement('a');
      a.href = url;
      a.download = name;
      a.click();
      setTimeout(() => URL.revokeObjectURL(url), 10_000);
    } catch (e) {
      setError(e instanceof Error ? e.message : String(e));
    }
  };

  return (
    <DuetFrame session={session}>
      <Panel
        title="Files"
        testId="duet-files"
        actions={
          <>
            {canUpload && (
              <>
                <input
                  ref={fileInput}
                  type="file"
                  multiple
                  hidden
                  aria-label="Files to upload"
                  onChange={(e) => void onFiles(e.target.files)}
                  data-testid="duet-upload-input"
                />
                <Button onClick={() => fileInput.current?.click()} disabled={link !== 'online'}>
                  <span aria-hidden="true">⇪</span> Upload
                </Button>
              </>
            )}
            {canSupervise && (
              <Button onClick={() => setNewFolder(true)} disabled={link !== 'online'}>
                New folder
              </Button>
            )}
            <Button onClick={files.refetch}>Refresh</Button>
          </>
        }
      >
        <div className="ui-row" role="group" aria-label="Folder" style={{ marginBottom: 10 }}>
          {ROOTS.map(([r, label]) => (
            <Button
              key={r}
              aria-pressed={r === root}
              variant={r === root ? 'primary' : 'secondary'}
              onClick={() => {
                setRoot(r);
                open(trimDir(dirs?.[r] ?? '0:/gcodes'));
              }}
              data-testid={`duet-root-${r}`}
            >
              {label}
            </Button>
          ))}
        </div>
        <div className="ui-row" style={{ marginBottom: 10 }}>
          {up !== null && (
            <Button onClick={() => open(up)} aria-label="Up one folder">
              <span aria-hidden="true">↑</span> Up
            </Button>
          )}
          <span className="mono" data-testid="duet-dir">
            {dir}
          </span>
        </div>
        {error && (
          <Notice tone="bad" title="File operation failed">
            {error}
          </Notice>
        )}
        {uploads.length > 0 && <Uploads session={session} />}
        {files.error && (
          <Notice tone="bad" title="Cannot list this folder">
            {files.error}
          </Notice>
        )}
        {files.loading && files.entries.length === 0 ? (
          <ProgressBar value={null} label="Loading" />
        ) : (
          <FileList
            session={session}
            root={root}
            dir={dir}
            entries={files.entries}
            onOpen={open}
            onRename={setRename}
            onDownload={download}
            canReadSystem={canSupervise}
          />
        )}
      </Panel>
      {rename && <RenameDialog session={session} dir={dir} entry={rename} onClose={() => setRename(null)} />}
      {newFolder && <NewFolderDialog session={session} dir={dir} onClose={() => setNewFolder(false)} />}
    </DuetFrame>
  );
}

function FileList(props: {
  session: DuetSession;
  root: Root;
  dir: string;
  entries: DirEntry[];
  onOpen: (dir: string) => void;
  onRename: (e: DirEntry) => void;
  onDownload: (path: string, name: string) => void;
  /** Files other than job files and the height map may hold passwords: supervisors only (access.ts). */
  canReadSystem: boolean;
}) {
  const { session, dir } = props;
  const ctx = session.ctx;
  if (props.entries.length === 0) return <p className="ui-muted">This folder is empty.</p>;
  return (
    <ul style={{ listStyle: 'none', margin: 0, padding: 0 }} data-testid="duet-file-list">
      {props.entries.map((e) => {
        const path = joinPath(dir, e.name);
        const isDir = e.type === 'd';
        const isJob = props.root === 'gCodes' && !isDir && /\.(g|gc|gcode|nc)$/i.test(e.name);
        return (
          <li
            key={e.name}
            className="ui-row"
            style={{ borderBottom: '1px solid var(--border)', padding: '6px 0', alignItems: 'center' }}
            data-testid="duet-file-row"
            data-name={e.name}
          >
            {isJob ? <JobThumb session={session} path={path} /> : <FileIcon folder={isDir} />}
            <div style={{ flex: 1, minWidth: 140 }}>
              {isDir ? (
                <Button onClick={() => props.onOpen(path)} style={{ fontWeight: 600 }}>
                  {e.name}
                </Button>
              ) : (
                <strong style={{ overflowWrap: 'anywhere' }}>{e.name}</strong>
              )}
              <div className="ui-muted" style={{ fontSize: 13 }}>
                {isDir ? 'folder' : formatBytes(e.size)} · {e.date ? formatDateTime(Date.parse(e.date)) : '—'}
              </div>
            </div>
            <div className="ui-row" style={{ gap: 6 }}>
              {isJob && (
                <>
                  <CommandButton
                    runner={ctx.commands}
                    snapshot={ctx.snapshot}
                    command={session.cmd.start}
                    args={{ path }}
                    variant="primary"
                    testId={`duet-start-${e.name}`}
                  >
                    <span aria-hidden="true">▶</span> Print
                  </CommandButton>
                  <CommandButton
                    runner={ctx.commands}
                    snapshot={ctx.snapshot}
                    command={session.cmd.simulate}
                    args={{ path }}
                  >
                    Simulate
                  </CommandButton>
                </>
              )}
              {props.root === 'macros' && !isDir && (
                <CommandButton
                  runner={ctx.commands}
                  snapshot={ctx.snapshot}
                  command={session.cmd.macro}
                  args={{ path }}
                  hideWhenNotAllowed
                >
                  Run
                </CommandButton>
              )}
              {!isDir && (props.canReadSystem || openToViewers(path)) && (
                <Button onClick={() => props.onDownload(path, e.name)}>Download</Button>
              )}
              <RoleGate least="supervisor">
                <Button onClick={() => props.onRename(e)}>Rename</Button>
              </RoleGate>
              <CommandButton
                runner={ctx.commands}
                snapshot={ctx.snapshot}
                command={session.cmd.del}
                args={{ path, dir: isDir }}
                hideWhenNotAllowed
              >
                Delete
              </CommandButton>
            </div>
          </li>
        );
      })}
    </ul>
  );
}

function FileIcon({ folder }: { folder: boolean }) {
  return (
    <svg width={48} height={40} viewBox="0 0 48 40" aria-hidden="true" style={{ flex: 'none' }}>
      {folder ? (
        <path d="M8 10h12l4 4h16v18H8z" fill="var(--warn-bg)" stroke="var(--warn)" strokeWidth={2} />
      ) : (
        <path d="M14 6h14l8 8v22H14z" fill="var(--panel-2)" stroke="var(--muted)" strokeWidth={2} />
      )}
    </svg>
  );
}

/** Its children only for users with at least the role `least`. */
function RoleGate(props: { least: 'operator' | 'supervisor'; children: ReactNode }) {
  return useCan(props.least) ? <>{props.children}</> : null;
}

function JobThumb({ session, path }: { session: DuetSession; path: string }) {
  // File info with thumbnails: a bounded query of the machine, not kept forever.
  const v = useFileInfo(session, path);
  const thumb =
    v && 'thumbnails' in v
      ? (v.thumbnails.find((t) => t.data && t.width <= 160) ?? v.thumbnails.find((t) => t.data) ?? null)
      : null;
  return (
    <span title={v && 'thumbnails' in v ? `${v.numLayers} layers · ${v.generatedBy ?? ''}` : undefined}>
      <Thumbnail thumb={thumb} size={48} alt={`thumbnail of ${path}`} />
    </span>
  );
}

function Uploads({ session }: { session: DuetSession }) {
  const uploads = useStoreSelect(session.store, (s) => s.uploads);
  return (
    <div data-testid="duet-uploads" style={{ marginBottom: 10 }}>
      {uploads.map((u) => (
        <div key={u.id} className="ui-row" style={{ marginBottom: 6 }}>
          <span style={{ minWidth: 160 }}>{u.name}</span>
          <div style={{ flex: 1, minWidth: 120 }}>
            <ProgressBar value={u.total ? u.loaded / u.total : null} label={`Upload of ${u.name}`} />
          </div>
          <span className="ui-muted">
            {u.status === 'uploading' ? `${formatBytes(u.loaded)} of ${formatBytes(u.total)}` : u.status}
            {u.error ? ` — ${u.error}` : ''}
          </span>
          {u.status === 'uploading' && (
            <Button
              variant="danger"
              onClick={() => session.cancelUpload(u.id)}
              data-testid="duet-upload-cancel"
            >
              Cancel
            </Button>
          )}
        </div>
      ))}
    </div>
  );
}

function RenameDialog({
  session,
  dir,
  entry,
  onClose,
}: {
  session: DuetSession;
  dir: string;
  entry: DirEntry;
  onClose: () => void;
}) {
  const ctx = session.ctx;
  const from = joinPath(dir, entry.name);
  const [to, setTo] = useState(from);
  const [conflict, setConflict] = useState(false);
  const [error, setError] = useState<string | null>(null);
  const [busy, setBusy] = useState(false);
  const go = async (force: boolean) => {
    setBusy(true);
    setError(null);
    try {
      await ctx.commands.run(session.cmd.move, { from, to, force });
      onClose();
    } catch (e) {
      // 409: the target exists — ask, then resend with force.
      if (e instanceof LinkError && e.status === 409) setConflict(true);
      else setError(e instanceof Error ? e.message : String(e));
    } finally {
      setBusy(false);
    }
  };
  return (
    <Dialog
      title={conflict ? 'Overwrite?' : `Rename or move ${entry.name}`}
      onCancel={onClose}
      testId="duet-rename"
      // The overwrite question is destructive: focus on Cancel when it is asked.
      focusKey={conflict ? 'conflict' : 'name'}
      actions={
        <>
          <Button onClick={onClose} data-autofocus={conflict || undefined}>
            Cancel
          </Button>
          {conflict ? (
            <Button
              variant="danger"
              busy={busy}
              onClick={() => void go(true)}
              data-testid="duet-rename-overwrite"
            >
              Overwrite {to}
            </Button>
          ) : (
            <Button
              variant="primary"
              busy={busy}
              disabled={!to.trim() || to === from}
              onClick={() => void go(false)}
              data-testid="duet-rename-ok"
            >
              Rename / move
            </Button>
          )}
        </>
      }
    >
      {conflict ? (
        <p>
          {to} already exists. Replace it with {entry.name}?
        </p>
      ) : (
        <Field label="New path" hint="A full path moves it to another folder" error={error}>
          {(id) => (
            <input
              id={id}
              className="ui-input mono"
              value={to}
              onChange={(e) => setTo(e.target.value)}
              style={{ minHeight: 44 }}
            />
          )}
        </Field>
      )}
    </Dialog>
  );
}

function NewFolderDialog({
  session,
  dir,
  onClose,
}: {
  session: DuetSession;
  dir: string;
  onClose: () => void;
}) {
  const ctx = session.ctx;
  const [name, setName] = useState('');
  const [error, setError] = useState<string | null>(null);
  const valid = name.trim() !== '' && !/[/\\:]/.test(name);
  return (
    <Dialog
      title="New folder"
      onCancel={onClose}
      actions={
        <>
          <Button onClick={onClose}>Cancel</Button>
          <Button
            variant="primary"
            disabled={!valid}
            onClick={() =>
              void ctx.commands
                .run(session.cmd.mkdir, { path: joinPath(dir, name.trim()) })
                .then(onClose)
                .catch((e: unknown) => setError(e instanceof Error ? e.message : String(e)))
            }
          >
            Create
          </Button>
        </>
      }
    >
      <Field
        label={`Folder name in ${dir}`}
        error={error ?? (name && !valid ? 'No slashes or colons' : null)}
      >
        {(id) => (
          <input
            id={id}
            className="ui-input"
            value={name}
            onChange={(e) => setName(e.target.value)}
            style={{ minHeight: 44 }}
          />
        )}
      </Field>
    </Dialog>
  );
}

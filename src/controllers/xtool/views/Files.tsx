import { useState } from 'react';
import { CommandButton, useCan, useStoreSelect } from '../../../fleet/react';
import type { TabProps } from '../../../fleet/contract';
import { describeError } from '../../../fleet/errors';
import { Button, DataTable, Field, Notice, Panel, ProgressBar, formatBytes } from '../../../ui';
import type { UploadTarget } from '../client';
import { FULL_WIDTH, GRID } from './layout';
import { useXtoolFiles } from '../queries';
import type { XtoolSession } from '../session';

type TargetKind = UploadTarget['kind'];

/** SD card: list, upload (with progress and verification), run remotely, delete. */
export function Files({ session }: TabProps<XtoolSession>) {
  const ctx = session.ctx;
  const up = useStoreSelect(session.detail, (s) => s.upload);
  // The folder listed (an on-demand read of the query layer), and the folder field being typed.
  const [dir, setDir] = useState('/');
  const [typed, setTyped] = useState('/');
  const list = useXtoolFiles(session, dir);
  const [file, setFile] = useState<File | null>(null);
  const [kind, setKind] = useState<TargetKind>('job');
  const [filename, setFilename] = useState('/jobs/');
  const isSupervisor = useCan('supervisor');

  /** Lists `to`; the folder already listed is read again (the user asked for it). */
  const refresh = (to = typed) => {
    setTyped(to);
    if (to === dir) list.refetch();
    else setDir(to);
  };

  const target: UploadTarget =
    kind === 'path'
      ? { kind: 'path', filename: filename.endsWith('/') ? filename + (file?.name ?? '') : filename }
      : { kind };
  const rows = (list.data?.name ?? []).map((path) => ({ path, dir: !/\.[a-z0-9]+$/i.test(path) }));

  return (
    <div className="ui-grid" style={GRID} data-testid="xtool-files">
      <Panel title="Upload to the laser">
        <Field label="G-code file">
          {(id) => (
            <input
              id={id}
              className="ui-input"
              type="file"
              style={FULL_WIDTH}
              accept=".gcode,.nc,.gc,.txt"
              data-testid="xtool-upload-file"
              onChange={(e) => setFile(e.target.files?.[0] ?? null)}
            />
          )}
        </Field>
        <Field
          label="Upload as"
          hint="A job or framing file waits on the laser until someone presses its button."
        >
          {(id) => (
            <select
              id={id}
              className="ui-input"
              style={FULL_WIDTH}
              value={kind}
              onChange={(e) => setKind(e.target.value as TargetKind)}
            >
              <option value="job">Job (/tmp.gcode) — starts with the button</option>
              <option value="frame">Framing (/frame.gcode) — traces the outline with the button</option>
              <option value="path">Copy to a path on the SD card</option>
            </select>
          )}
        </Field>
        {kind === 'path' && (
          <Field label="Path on the SD card" hint="The folder must exist.">
            {(id) => (
              <input
                id={id}
                className="ui-input"
                style={FULL_WIDTH}
                value={filename}
                onChange={(e) => setFilename(e.target.value)}
              />
            )}
          </Field>
        )}
        <div className="ui-row">
          {file ? (
            <CommandButton
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={session.upload}
              args={{ file, name: file.name, target }}
              variant="primary"
              testId="xtool-upload"
            >
              Upload {file.name}
            </CommandButton>
          ) : (
            <Button disabled>Choose a file to upload</Button>
          )}
        </div>
        {up && (
          <div style={{ marginTop: 12 }} data-testid="xtool-upload-state">
            <ProgressBar
              value={up.phase === 'verifying' ? null : up.total ? up.loaded / up.total : null}
              label="upload progress"
            />
            <p className="ui-muted">
              {up.name} → {up.path}:{' '}
              {up.phase === 'uploading' && `${formatBytes(up.loaded)} of ${formatBytes(up.total)}`}
              {up.phase === 'verifying' &&
                'checking the SD card (the laser says "ok" even when an upload failed)…'}
            </p>
            {up.phase === 'done' && (
              <Notice tone="ok" title="Uploaded and verified">
                {up.message}
              </Notice>
            )}
            {up.phase === 'failed' && (
              <Notice tone="bad" title="Upload failed">
                {up.message}
              </Notice>
            )}
          </div>
        )}
      </Panel>
      <Panel
        title="SD card"
        actions={
          <Button onClick={() => refresh(dir)} busy={list.fetching} disabled={list.fetching}>
            Refresh
          </Button>
        }
      >
        <form
          className="ui-row"
          onSubmit={(e) => {
            e.preventDefault();
            refresh();
          }}
          style={{ marginBottom: 10 }}
        >
          <input
            className="ui-input"
            aria-label="Folder"
            value={typed}
            onChange={(e) => setTyped(e.target.value)}
          />
          <Button type="submit">List</Button>
          {dir !== '/' && <Button onClick={() => refresh(dir.replace(/\/[^/]*\/?$/, '') || '/')}>Up</Button>}
        </form>
        {list.error && (
          <Notice tone="warn" title="Could not list the SD card">
            {describeError(list.error)}
          </Notice>
        )}
        <DataTable
          testId="xtool-file-table"
          rows={rows}
          rowKey={(r) => r.path}
          empty={list.data ? 'The folder is empty.' : list.loading ? 'Listing…' : 'Not listed yet.'}
          columns={[
            { key: 'path', label: 'File', render: (r) => <span className="mono">{r.path}</span> },
            {
              key: 'actions',
              label: <span className="sr-only">Actions</span>,
              render: (r) => (
                <div className="ui-row">
                  {r.dir ? (
                    <Button onClick={() => refresh(r.path)}>Open</Button>
                  ) : (
                    isSupervisor && (
                      <CommandButton
                        runner={ctx.commands}
                        snapshot={ctx.snapshot}
                        command={session.runFile}
                        args={{ path: r.path }}
                        hideWhenNotAllowed
                      >
                        Run now
                      </CommandButton>
                    )
                  )}
                  <CommandButton
                    runner={ctx.commands}
                    snapshot={ctx.snapshot}
                    command={session.deleteFile}
                    args={{ path: r.path }}
                    hideWhenNotAllowed
                  >
                    Delete
                  </CommandButton>
                </div>
              ),
            },
          ]}
        />
      </Panel>
    </div>
  );
}

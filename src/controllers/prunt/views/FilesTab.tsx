import { useState } from 'react';
import { useStore } from 'zustand';
import type { TabProps } from '../../../fleet/contract';
import { describeError } from '../../../fleet/errors';
import { useMachineQuery } from '../../../fleet/kernel';
import { CommandButton } from '../../../fleet/react';
import { Button, DataTable, formatBytes, Notice, Panel } from '../../../ui';
import { UploadStatus } from '../../../ui/UploadStatus';
import { safeExternalHref } from '../../../ui/safe-url';
import { FILES_STALE_MS, PRUNT_KEYS } from '../queries';
import type { PruntSession } from '../session';
import './prunt.css';

/**
 * The controller's "update available" URL: a link only when it is an external https page
 * (opened without opener or referrer); anything else (a console path, `%2e%2e/…`, `http:`,
 * `javascript:`…) is shown as plain text, never followed.
 */
export function UpdateLink({ url }: { url: string }) {
  const href = safeExternalHref(url);
  if (!url.trim()) return <span className="ui-muted">no link given</span>;
  if (!href)
    return (
      <span className="mono" data-testid="prunt-update-url">
        {url}
      </span>
    );
  return (
    <a href={href} target="_blank" rel="noopener noreferrer" data-testid="prunt-update-url">
      {href}
    </a>
  );
}

/** Download link of an uploaded file; none when the name would lead out of `/uploads/`. */
function DownloadLink({ session, name }: { session: PruntSession; name: string }) {
  const url = session.client.fileUrl(name);
  if (!url)
    return (
      <span
        className="ui-muted"
        title="This file name cannot be downloaded safely"
        data-testid={`download-${name}`}
      >
        No download
      </span>
    );
  return (
    <a className="ui-button" href={url} download={name} data-testid={`download-${name}`}>
      Download
    </a>
  );
}

/** Files in `/uploads/`: list, upload with progress, download, run; and the update check. */
export function FilesTab({ session }: TabProps<PruntSession>) {
  // An on-demand read, fresh for a while; an upload invalidates it (the list refetches).
  const list = useMachineQuery(
    session.ctx.queries,
    PRUNT_KEYS.files,
    (signal) => session.client.uploads(signal),
    { staleTimeMs: FILES_STALE_MS },
  );
  const files = list.data ?? null;
  const upload = useStore(session.uploads.store);
  const update = useStore(session.store, (s) => s.update);
  const [picked, setPicked] = useState<File | null>(null);
  const run = session.ctx.commands;
  return (
    <div className="pr-grid" data-testid="prunt-files">
      <Panel title="Files" actions={<Button onClick={list.refetch}>Refresh</Button>} className="pr-wide">
        {list.error && <Notice tone="bad">{describeError(list.error)}</Notice>}
        <DataTable
          rows={files ?? []}
          rowKey={(f) => f}
          empty={files === null ? 'Loading…' : 'No files uploaded.'}
          columns={[
            { key: 'name', label: 'File', render: (f) => <span className="mono">{f}</span> },
            {
              key: 'actions',
              label: <span className="sr-only">Actions</span>,
              align: 'right',
              render: (f) => (
                <span className="ui-row" style={{ justifyContent: 'flex-end' }}>
                  <DownloadLink session={session} name={f} />
                  <CommandButton
                    runner={run}
                    snapshot={session.ctx.snapshot}
                    command={session.cmd.runFile}
                    args={f}
                    variant="primary"
                    testId={`run-${f}`}
                  >
                    Run
                  </CommandButton>
                </span>
              ),
            },
          ]}
        />
      </Panel>
      <Panel title="Upload">
        <div className="ui-row pr-upload">
          <input
            type="file"
            className="ui-input"
            accept=".gcode,.gco,.g,.nc,text/plain"
            aria-label="File to upload"
            onChange={(e) => setPicked(e.target.files?.[0] ?? null)}
          />
          {picked && (
            <CommandButton
              runner={run}
              snapshot={session.ctx.snapshot}
              command={session.cmd.upload}
              args={{ name: picked.name, body: picked }}
            >
              Upload {picked.name} ({formatBytes(picked.size)})
            </CommandButton>
          )}
        </div>
        <UploadStatus state={upload} onCancel={() => session.uploads.cancel()} testId="prunt-upload" />
      </Panel>
      <Panel
        title="Software update"
        actions={<Button onClick={() => void session.refreshUpdateCheck()}>Check result again</Button>}
      >
        {!update ? (
          <p className="ui-muted">Not known yet.</p>
        ) : update.error ? (
          <Notice tone="warn" title="The last update check failed">
            {update.error}
          </Notice>
        ) : update.result?.Available ? (
          <Notice tone="info" title="An update is available">
            <UpdateLink url={update.result.URL} />
          </Notice>
        ) : (
          <p>No update available{update.result?.URL ? ` (${update.result.URL})` : ''}.</p>
        )}
        <p className="ui-muted">This shows the controller's last check; it does not start one.</p>
      </Panel>
    </div>
  );
}

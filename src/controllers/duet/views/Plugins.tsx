import { useRef, useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Badge, Button, DataTable, Notice, Panel } from '../../../ui';
import type { DuetSession } from '../session';
import type { Plugin } from '../wire';
import { DuetFrame } from './common';

/** Plugins (supervisor): list from the model, install a ZIP, uninstall, start, stop. */
export function Plugins({ session }: TabProps<DuetSession>) {
  const ctx = session.ctx;
  const plugins = useStoreSelect(session.store, (s) => s.model?.plugins ?? null);
  const rows: Plugin[] = Object.values(plugins ?? {});
  const input = useRef<HTMLInputElement>(null);
  const [pending, setPending] = useState<File | null>(null);
  const [error, setError] = useState<string | null>(null);
  return (
    <DuetFrame session={session}>
      <Panel
        title="Plugins"
        testId="duet-plugins"
        actions={
          <>
            <input
              ref={input}
              type="file"
              accept=".zip,application/zip"
              hidden
              aria-label="Plugin file (ZIP)"
              onChange={(e) => {
                setPending(e.target.files?.[0] ?? null);
                setError(null);
              }}
            />
            <Button onClick={() => input.current?.click()}>Choose plugin ZIP…</Button>
          </>
        }
      >
        {pending && (
          <div className="ui-row" style={{ marginBottom: 10 }}>
            <span>{pending.name}</span>
            <CommandButton
              runner={ctx.commands}
              snapshot={ctx.snapshot}
              command={session.cmd.pluginInstall}
              args={{ file: pending, name: pending.name }}
              onDone={() => setPending(null)}
              onError={setError}
            >
              Install
            </CommandButton>
          </div>
        )}
        {error && <Notice tone="bad">{error}</Notice>}
        <DataTable
          rowKey={(p) => p.id}
          rows={rows}
          empty="No plugins installed."
          columns={[
            { key: 'name', label: 'Plugin', render: (p) => <strong>{p.name || p.id}</strong> },
            { key: 'version', label: 'Version' },
            { key: 'author', label: 'Author' },
            {
              key: 'state',
              label: 'State',
              render: (p) =>
                p.sbcExecutable ? (
                  <Badge tone={p.pid > 0 ? 'ok' : 'muted'}>
                    {p.pid > 0 ? `running (pid ${p.pid})` : 'stopped'}
                  </Badge>
                ) : (
                  <Badge tone="info" plain>
                    web only
                  </Badge>
                ),
            },
            {
              key: 'actions',
              label: <span className="sr-only">Actions</span>,
              render: (p) => (
                <span className="ui-row" style={{ gap: 6 }}>
                  {p.sbcExecutable && p.pid <= 0 && (
                    <CommandButton
                      runner={ctx.commands}
                      snapshot={ctx.snapshot}
                      command={session.cmd.pluginStart}
                      args={{ id: p.id }}
                    >
                      Start
                    </CommandButton>
                  )}
                  {p.sbcExecutable && p.pid > 0 && (
                    <CommandButton
                      runner={ctx.commands}
                      snapshot={ctx.snapshot}
                      command={session.cmd.pluginStop}
                      args={{ id: p.id }}
                    >
                      Stop
                    </CommandButton>
                  )}
                  <CommandButton
                    runner={ctx.commands}
                    snapshot={ctx.snapshot}
                    command={session.cmd.pluginUninstall}
                    args={{ id: p.id }}
                  >
                    Uninstall
                  </CommandButton>
                </span>
              ),
            },
          ]}
        />
      </Panel>
    </DuetFrame>
  );
}

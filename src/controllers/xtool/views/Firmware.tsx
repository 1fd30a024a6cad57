import { useState } from 'react';
import type { TabProps } from '../../../fleet/contract';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Button, Field, KeyValues, Notice, Panel, ProgressBar, formatBytes } from '../../../ui';
import type { XtoolSession } from '../session';
import { FULL_WIDTH } from './layout';

/** Firmware upgrade (POST /upgrade): supervisor only, dangerous, confirmed twice. */
export function Firmware({ session }: TabProps<XtoolSession>) {
  const ctx = session.ctx;
  const d = useStoreSelect(session.detail, (s) => ({
    version: s.identity.version,
    sn: s.identity.sn,
    up: s.upgrade,
  }));
  const [file, setFile] = useState<File | null>(null);
  return (
    <Panel title="Firmware" testId="xtool-firmware">
      <KeyValues
        items={[
          ['Current firmware', d.version],
          ['Serial', d.sn],
        ]}
      />
      <Notice tone="warn" title="Upgrading firmware can leave the laser unusable">
        Use only a firmware file for this model from xTool. Keep the laser powered and connected until it
        restarts.
      </Notice>
      <Field label="Firmware file (.bin)">
        {(id) => (
          <input
            id={id}
            className="ui-input"
            type="file"
            style={FULL_WIDTH}
            accept=".bin"
            onChange={(e) => setFile(e.target.files?.[0] ?? null)}
          />
        )}
      </Field>
      {file ? (
        <CommandButton
          runner={ctx.commands}
          snapshot={ctx.snapshot}
          command={session.upgrade}
          args={{ file, name: file.name }}
          details={<p>Current firmware: {d.version ?? 'unknown'}</p>}
        >
          Upgrade to {file.name} ({formatBytes(file.size)})
        </CommandButton>
      ) : (
        <Button disabled>Choose a firmware file</Button>
      )}
      {d.up && (
        <div style={{ marginTop: 12 }}>
          <ProgressBar value={d.up.total ? d.up.loaded / d.up.total : null} label="firmware upload" />
          {d.up.message && (
            <Notice
              tone={d.up.phase === 'failed' ? 'bad' : 'ok'}
              title={d.up.phase === 'failed' ? 'Failed' : 'Done'}
            >
              {d.up.message}
            </Notice>
          )}
        </div>
      )}
    </Panel>
  );
}

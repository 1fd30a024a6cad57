import { useEffect } from 'react';
import { useStore } from 'zustand';
import { CommandButton } from '../../../fleet/react';
import { Notice } from '../../../ui';
import type { PruntSession } from '../session';
import { LIVE_RATES } from '../session';

/** While mounted, the machine page asks the controller for the chosen tick rate. */
export function useWatchLive(session: PruntSession): void {
  useEffect(() => session.watchLive(), [session]);
}

export function RateSelect(props: { session: PruntSession }) {
  const hz = useStore(props.session.store, (s) => s.liveHz);
  return (
    <label className="pr-rate">
      Updates
      <select
        className="ui-input"
        value={hz}
        onChange={(e) => props.session.setLiveRate(Number(e.target.value))}
        aria-label="Status updates per second"
        data-testid="prunt-rate"
      >
        {LIVE_RATES.map((r) => (
          <option key={r} value={r}>
            {r} / s
          </option>
        ))}
      </select>
    </label>
  );
}

/** Startup state and server exceptions, with the supervisor's "allow firmware update". */
export function StartupBanner(props: { session: PruntSession }) {
  const { session } = props;
  const startup = useStore(session.store, (s) => s.startup);
  const exception = useStore(session.store, (s) => s.exception);
  return (
    <>
      {startup === 'Update_Required' && (
        <div className="ui-notice tone-warn" role="alert" data-testid="prunt-update-required">
          <strong>Firmware update required</strong>
          <p>
            The board firmware must be updated before the machine can start. Updates are never applied
            unattended: a supervisor has to allow it.
          </p>
          <div className="ui-row" style={{ marginTop: 8 }}>
            <CommandButton
              runner={session.ctx.commands}
              snapshot={session.ctx.snapshot}
              command={session.cmd.allowFirmwareUpdate}
              args={undefined}
            />
          </div>
        </div>
      )}
      {startup === 'Update_Running' && (
        <Notice tone="info" title="Firmware update running">
          Do not switch the machine off.
        </Notice>
      )}
      {startup === 'Waiting' && <Notice tone="info" title="The server is starting up" />}
      {startup?.startsWith('unknown') && <Notice tone="warn" title={`Startup state ${startup}`} />}
      {exception && (
        <Notice
          tone={exception.fatal ? 'bad' : 'warn'}
          title={exception.fatal ? 'Fatal server exception' : 'Server exception'}
        >
          {exception.message}
        </Notice>
      )}
    </>
  );
}

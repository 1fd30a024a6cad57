import { useStore } from 'zustand';
import { useNow } from '../../fleet/react';
import { Button } from '../../ui';
import { reachStore, retryNow } from './reach';
import './pwa.css';

/**
 * "Console unreachable — retrying": shown while the console's server does not answer at boot
 * (src/app/pwa/reach.ts), over whatever page the address names; gone by itself once it answers.
 */
export function ConsoleUnreachable() {
  const unreachable = useStore(reachStore, (s) => s.unreachable);
  return unreachable ? <Unreachable /> : null;
}

function Unreachable() {
  const offline = useStore(reachStore, (s) => s.offline);
  const nextTryAt = useStore(reachStore, (s) => s.nextTryAt);
  const now = useNow(1000);
  const inS = nextTryAt === null ? 0 : Math.ceil((nextTryAt - now) / 1000);
  return (
    <div className="console-unreachable" data-testid="console-unreachable">
      {/* The live region holds the message, not the countdown (no announcement every second). */}
      <div role="status">
        <h2>Console unreachable — retrying</h2>
        <p>
          {offline
            ? 'This device has no network.'
            : `The Shopdeck server (${location.host}) does not answer.`}{' '}
          Nothing is sent to any machine until it does.
        </p>
      </div>
      <div className="console-unreachable-row">
        <span>{inS > 0 ? `Next try in ${inS} s` : 'Trying…'}</span>
        <Button onClick={retryNow}>Try now</Button>
      </div>
    </div>
  );
}

import { useState } from 'react';
import { describeError } from '../../../fleet/errors';
import { useBlockedReason } from '../../../fleet/kernel';
import { CommandButton, useStoreSelect } from '../../../fleet/react';
import { Panel } from '../../../ui';
import { LockableSlider } from '../../../ui/Lockable';
import { OVERRIDE_PHRASES, overrideLine } from '../phrases';
import type { G2coreSession } from '../session';

const STEPS = [-0.1, 0.1] as const;

/**
 * Feed and spindle overrides: a slider (locked against touch on touch screens and the kiosk page,
 * src/ui/Lockable.tsx) sent when released, and ±10 % / 100 % buttons. Also on the kiosk page.
 */
export function Overrides({ session }: { session: G2coreSession }) {
  const { mfo, sso, enabled } = useStoreSelect(session.detail, (d) => ({
    mfo: typeof d.sr.mfo === 'number' ? d.sr.mfo : null,
    sso: typeof d.sr.sso === 'number' ? d.sr.sso : null,
    enabled: d.overrides,
  }));
  if (mfo === null && sso === null) return null;
  return (
    <Panel title="Overrides">
      {mfo !== null && <OverrideRow session={session} k="mfo" value={mfo} on={enabled.mfoe} />}
      {sso !== null && <OverrideRow session={session} k="sso" value={sso} on={enabled.ssoe} />}
    </Panel>
  );
}

function OverrideRow(props: { session: G2coreSession; k: 'mfo' | 'sso'; value: number; on: boolean | null }) {
  const { session, k, value, on } = props;
  const phrase = OVERRIDE_PHRASES[k];
  const what = phrase.what;
  const { commands: runner, snapshot } = session.ctx;
  const blocked = useBlockedReason(runner, snapshot, session.setOverride);
  const [error, setError] = useState<string | null>(null);
  return (
    <div style={{ marginBottom: 12 }} data-testid={`g2-override-${k}`}>
      {on === false && (
        <div className="ui-muted" data-testid={`g2-override-${k}-off`}>
          {overrideLine(phrase, value, on)}. Turn on “{phrase.setting}” in Settings to use it.{' '}
          <span className="small" title="g2core's own setting">
            (g2core: {phrase.enable})
          </span>
        </div>
      )}
      <LockableSlider
        label={what}
        value={Math.round(value * 100)}
        min={5}
        max={200}
        step={5}
        format={(v) => `${v} %`}
        // "Already being sent" is the slider's own busy state.
        disabledReason={blocked === 'Already being sent' ? null : blocked}
        testId={`g2-override-${k}-slider`}
        onCommit={async (v) => {
          setError(null);
          try {
            await runner.run(session.setOverride, { key: k, value: v / 100 });
            return true;
          } catch (e) {
            setError(describeError(e));
            return false;
          }
        }}
      />
      {error && (
        <span className="ui-muted" role="alert" style={{ color: 'var(--bad)' }}>
          {error}
        </span>
      )}
      <div className="g2-choices">
        {STEPS.map((d) => (
          <CommandButton
            key={d}
            runner={runner}
            snapshot={snapshot}
            command={session.setOverride}
            args={{ key: k, value: Math.round(Math.min(2, Math.max(0.05, value + d)) * 100) / 100 }}
          >
            {d > 0 ? '+10 %' : '−10 %'}
          </CommandButton>
        ))}
        <CommandButton
          runner={runner}
          snapshot={snapshot}
          command={session.setOverride}
          args={{ key: k, value: 1 }}
        >
          100 %
        </CommandButton>
      </div>
    </div>
  );
}

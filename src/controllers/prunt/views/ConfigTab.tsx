import { useEffect, useState } from 'react';
import { useStore } from 'zustand';
import type { TabProps } from '../../../fleet/contract';
import { CommandButton, useCan } from '../../../fleet/react';
import { FormView, ReviewChanges } from '../../../forms/FormView';
import type { FormModel } from '../../../forms/model';
import { Badge, Button, Notice, Panel } from '../../../ui';
import type { PruntSession } from '../session';
import './prunt.css';

/** The config editor: a form generated from the controller's schema. */
export function ConfigTab({ session }: TabProps<PruntSession>) {
  const phase = useStore(session.config, (s) => s.phase);
  const error = useStore(session.config, (s) => s.error);
  const model = useStore(session.config, (s) => s.model);
  const canEdit = useCan('supervisor');
  useEffect(() => {
    void session.openConfig();
  }, [session]);
  if (!model) {
    return (
      <Panel title="Configuration">
        {phase === 'error' ? (
          <Notice tone="bad" title="Could not load the configuration">
            {error}
            <Button onClick={() => void session.loadConfig(null)}>Try again</Button>
          </Notice>
        ) : (
          <p className="ui-muted">Loading the schema and values from the controller…</p>
        )}
      </Panel>
    );
  }
  return (
    <Panel title="Configuration" testId="prunt-config">
      <ConfigBar session={session} model={model} canEdit={canEdit} />
      {phase === 'error' && (
        <Notice tone="bad" title="Could not reload the configuration">
          {error} — your unsaved edits are kept.
        </Notice>
      )}
      <FormView
        model={model}
        assetBase={session.client.http.base}
        readOnly={!canEdit}
        readOnlyReason="Changing the configuration needs the supervisor role: you can look, not edit."
      />
    </Panel>
  );
}

function ConfigBar(props: { session: PruntSession; model: FormModel; canEdit: boolean }) {
  const { session, model } = props;
  const [review, setReview] = useState(false);
  const edits = useStore(model.store, (s) => Object.keys(s.edits).length);
  const invalid = useStore(model.store, (s) => Object.keys(s.localErrors).length);
  const lastSave = useStore(session.config, (s) => s.lastSave);
  const offerReload = useStore(session.config, (s) => s.offerReload);
  const notice = useStore(session.config, (s) => s.notice);
  const phase = useStore(session.config, (s) => s.phase);
  const run = session.ctx.commands;
  return (
    <>
      <div className="pr-config-bar" data-testid="prunt-config-bar">
        {edits > 0 ? (
          <Badge tone="info">
            {edits} unsaved edit{edits === 1 ? '' : 's'} (kept on this device)
          </Badge>
        ) : (
          <Badge tone="muted">No unsaved edits</Badge>
        )}
        {invalid > 0 && <Badge tone="bad">{invalid} invalid</Badge>}
        {props.canEdit && (
          <>
            <Button
              variant="primary"
              disabled={edits === 0}
              onClick={() => setReview(true)}
              data-testid="prunt-review"
            >
              Review changes…
            </Button>
            <Button disabled={edits === 0} onClick={() => model.discardAll()}>
              Discard edits
            </Button>
          </>
        )}
        <Button onClick={() => void session.loadConfig(null)} disabled={phase === 'loading'}>
          Reload from controller
        </Button>
      </div>
      {notice && <Notice tone="info">{notice}</Notice>}
      {lastSave && (
        <Notice
          tone={lastSave.saved ? 'ok' : 'bad'}
          title={lastSave.saved ? 'Saved' : 'Not saved'}
          testId="prunt-save-result"
        >
          {lastSave.message}
        </Notice>
      )}
      {offerReload && props.canEdit && (
        <div className="ui-notice tone-info" data-testid="prunt-offer-reload">
          <strong>Reload the server to apply</strong>
          <p>Prunt applies a saved configuration when the server reloads.</p>
          <div className="ui-row" style={{ marginTop: 8 }}>
            <CommandButton
              runner={run}
              snapshot={session.ctx.snapshot}
              command={session.cmd.reloadServer}
              args={undefined}
            />
          </div>
        </div>
      )}
      {review && (
        <ReviewChanges
          model={model}
          onCancel={() => setReview(false)}
          note={<p className="ui-muted">Only these values are sent; the controller may still reject them.</p>}
          actions={
            <>
              <Button onClick={() => setReview(false)} data-autofocus>
                Keep editing
              </Button>
              <CommandButton
                runner={run}
                snapshot={session.ctx.snapshot}
                command={session.cmd.saveConfig}
                args={undefined}
                variant="primary"
                onDone={() => setReview(false)}
                onError={() => setReview(false)}
              >
                Save {edits} change{edits === 1 ? '' : 's'}
              </CommandButton>
            </>
          }
        />
      )}
    </>
  );
}
